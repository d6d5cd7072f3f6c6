"""Memory is bounded by the batch, not the photon count, for the estimators
that stream (DETP, Impact Count); Photon Maps keep every impact, and a run
that would outgrow the device stops after its first batch with the reason.

Peak memory is measured in a process of each run's own (its high-water
mark, VmHWM, from after the kernels are built), and the test checks the
measurement can see growth: the Photon Map's peak does
grow with the photons, by about its impacts' bytes.
"""

import json
import subprocess
import sys

import pytest
from conftest import ROOT

import oclgi
from oclgi.errors import OclgiError

SCRIPT = r"""
import json, sys
import oclgi
method = sys.argv[1]
engine = oclgi.Engine(oclgi.load_file(sys.argv[2]), batch_bytes=8 << 20, progress=False)
pts = engine.camera_points(width=16, height=16)
opts = {"k": 20} if method == "photon_map" else {}
# Kernels compile (and PoCL specialises them per launch size) in a first,
# full-size batch of a short run; a compile peaks at hundreds of MiB. The
# high-water mark is then reset (Linux clear_refs) before each run measured,
# smallest first: a larger run's peak cannot hide under a smaller one's.
engine.irradiance(pts, method=method, photons=20_000, **opts)
for photons in map(int, sys.argv[3:]):
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    est = engine.irradiance(pts, method=method, photons=photons, **opts)
    del est.estimator
    hwm = [line for line in open("/proc/self/status") if line.startswith("VmHWM:")][0]
    print(json.dumps({"peak_kib": int(hwm.split()[1]), "segments": est.stats.segments}))
    del est
"""


def _peaks(method, *photons):
    """(peak bytes, segments) of each run, in one process of the method's own."""
    res = subprocess.run([sys.executable, "-c", SCRIPT, method, str(ROOT / "scenes" / "cornell_box.toml"),
                          *map(str, photons)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    out = [json.loads(line) for line in res.stdout.strip().splitlines()[-len(photons):]]
    return [(o["peak_kib"] * 1024, o["segments"]) for o in out]


def test_streaming_estimators_peak_memory_does_not_grow_with_photons():
    small, large = 100_000, 700_000
    for method in ("detp_disc_index", "impact"):
        (p0, _), (p1, segs) = _peaks(method, small, large)
        # seven times the photons (2.3 million segments, ~80 MB if kept): the same peak within noise
        assert p1 - p0 < 24 << 20, f"{method}: peak {p0 / 2**20:.0f} -> {p1 / 2**20:.0f} MiB"
    # the measurement sees growth where there is some: the Photon Map keeps every impact (36 bytes)
    (p0, _), (p1, segs) = _peaks("photon_map", small, large)
    assert p1 - p0 > 0.5 * segs * 36, f"photon_map: peak {p0 / 2**20:.0f} -> {p1 / 2**20:.0f} MiB"


def test_photon_map_that_would_outgrow_the_device_stops_after_its_first_batch(scenes_dir):
    engine = oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml"))
    pts = engine.camera_points(width=8, height=8)
    run = engine.run(pts, method="photon_map", photons=200_000, k=10)
    run.set_batch(10_000)
    run.estimator.limit = 100_000  # as a device with room for 10^5 impacts; the run makes about 4 x 10^5
    with pytest.raises(OclgiError, match=r"200,000 photons would make about [\d,]+ impacts .* more than the "
                                         r"100,000 this device holds"):
        run.complete(False)
    assert run.traced == 10_000  # stopped at its start
    # under the limit the same run completes
    run = engine.run(pts, method="photon_map", photons=20_000, k=10)
    run.estimator.limit = 100_000
    assert run.complete(False).stats.photons == 20_000
