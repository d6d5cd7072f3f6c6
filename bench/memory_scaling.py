"""Peak memory against the photon count: flat for the streaming estimators.

Each (method, photons) runs in a process of its own, and its peak resident
memory (ru_maxrss: host memory, which on a CPU device holds the device
buffers too) is recorded with the run's time and segments:

    python bench/memory_scaling.py --photons 1e6,1e7,1e8 --methods detp_disc_index,impact
    python bench/memory_scaling.py --photons 1e5,1e6 --methods photon_map      # for contrast: it grows

Writes a markdown table to bench/results/memory_scaling.md (or -o).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from common import RESULTS, ROOT, arguments

CHILD = r"""
import json, resource, sys, time
import oclgi
method, photons, scene = sys.argv[1], int(float(sys.argv[2])), sys.argv[3]
engine = oclgi.Engine(oclgi.load_file(scene), progress=False)
pts = engine.camera_points(width=64, height=64)
opts = {"k": 50} if method == "photon_map" else {}
t0 = time.perf_counter()
est = engine.irradiance(pts, method=method, photons=photons, **opts)
print(json.dumps({"peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "seconds": time.perf_counter() - t0, "segments": est.stats.segments,
                  "device": engine.queue.device.name.strip()}))
"""


def main() -> None:
    args = arguments(__doc__, photons="1e6,1e7,1e8", methods="detp_disc_index,impact",
                     scene=str(ROOT / "scenes" / "cornell_box.toml"),
                     output=dict(short="-o", type=Path, default=RESULTS / "memory_scaling.md"))
    rows = []
    for method in args.methods.split(","):
        for photons in args.photons.split(","):
            res = subprocess.run([sys.executable, "-c", CHILD, method, photons, args.scene],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                sys.exit(f"{method} {photons}: {res.stderr.strip().splitlines()[-1]}")
            rows.append((method, n := int(float(photons)), r := json.loads(res.stdout.strip().splitlines()[-1])))
            print(f"{method:18s} {n:>12,} photons  peak {r['peak_mib']:8.1f} MiB  "
                  f"{r['seconds']:7.1f} s  {r['segments']:,} segments", flush=True)
    device = rows[0][2]["device"] if rows else "?"
    lines = [f"# Peak memory against photon count ({time.strftime('%Y-%m-%d')}, {device}, 64x64 camera points, "
             f"{Path(args.scene).name})", "", "| method | photons | segments | peak RSS (MiB) | time (s) |",
             "|---|---:|---:|---:|---:|"]
    lines += [f"| {m} | {n:,} | {r['segments']:,} | {r['peak_mib']:.1f} | {r['seconds']:.1f} |" for m, n, r in rows]
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
