"""Peak memory against the photon count: flat for the streaming estimators.

Each (method, photons) runs in a process of its own, and its peak resident
memory (ru_maxrss: host memory, which on a CPU device holds the device
buffers too) is recorded with the run's time and segments:

    python bench/memory_scaling.py --photons 1e6,1e7,1e8 --methods detp_disc_index,impact
    python bench/memory_scaling.py --photons 1e5,1e6 --methods photon_map      # for contrast: it grows

Writes a markdown table to bench/results/memory_scaling.md (or -o).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

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
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", default="1e6,1e7,1e8")
    ap.add_argument("--methods", default="detp_disc_index,impact")
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "cornell_box.toml"))
    ap.add_argument("-o", "--output", type=Path, default=ROOT / "bench" / "results" / "memory_scaling.md")
    args = ap.parse_args()
    rows = []
    for method in args.methods.split(","):
        for photons in args.photons.split(","):
            res = subprocess.run([sys.executable, "-c", CHILD, method, photons, args.scene],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                sys.exit(f"{method} {photons}: {res.stderr.strip().splitlines()[-1]}")
            r = json.loads(res.stdout.strip().splitlines()[-1])
            rows.append((method, int(float(photons)), r))
            print(f"{method:18s} {int(float(photons)):>12,} photons  peak {r['peak_mib']:8.1f} MiB  "
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
