"""Print the result tables (as bench/HISTORY.md, "Results", has them) from a benchmark JSON.

    python bench/report.py [bench/results/latest.json]

The rates come from each benchmark's median round (``extra_info``), so the
tables read the same numbers the JSON keeps; ``cores used`` shows whether the
timed work really had the machine (about 2 on 2 idle cores).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


# Each table: its header, which benchmarks' rows it holds, the cells of a row.
TABLES = [
    ("| scene | triangles | paths | segments/path | Msegments/s | cores used |\n|---|---:|---:|---:|---:|---:|",
     lambda e: "segments" in e and "scene" in e,  # test_detp records segments of no scene
     lambda e: f"{e['scene']} | {e['triangles']:,} | {e['paths']:,} | {e['segments_per_path']} "
               f"| {e.get('msegments_per_s', '-')} | {e['cores_used']}"),
    ("| mesh | rays | hit | oclgi Mrays/s | Embree Mrays/s | oclgi / Embree | hit/miss agree | same triangle "
     "| nearer hit missed | cores used |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
     lambda e: "n_rays" in e and "boxes" not in e,
     lambda e: f"{e['scene']} ({e['triangles']:,} tris) | {e['rays']} | {e['hit_fraction']:.1%} "
               f"| {e.get('oclgi_mrays_per_s', '-')} | {e.get('embree_mrays_per_s', '-')} "
               f"| {e.get('ratio_oclgi_over_embree', '-')} | {e['hit_agreement']:.4%} "
               f"| {e['same_triangle']:.4%} | {e['nearer_hit_missed']} | {e['cores_used']}"),
    ("| movable boxes | instances | rays ending on a box | grouped Mrays/s | one at a time Mrays/s "
     "| grouped / one at a time | cores used |\n|---:|---:|---:|---:|---:|---:|---:|",
     lambda e: "boxes" in e,
     lambda e: f"{e['boxes']} | {e['instances']} | {e['hit_boxes']:.1%} | {e.get('grouped_mrays_per_s', '-')} "
               f"| {e.get('one_by_one_mrays_per_s', '-')} | {e.get('grouped_over_one_by_one', '-')} "
               f"| {e['cores_used']}"),
    ("| triangles | oclgi build s | Mtriangles/s | nodes | depth | Embree build s |\n|---:|---:|---:|---:|---:|---:|",
     lambda e: "nodes" in e,
     lambda e: f"{e['triangles']:,} | {e.get('seconds', '-')} | {e.get('mtris_per_s', '-')} "
               f"| {e['nodes']:,} | {e['depth']} | {e['embree_build_s']}"),
]


def main(path):
    data = json.loads(Path(path).read_text())
    m = data["machine_info"]
    print(f"{m['cpu']['brand_raw']}, {m['cpu_count']} cores; {m['opencl_device']}; "
          f"{m['opencl_platform'].split('  ')[0]}; embreex {m['embreex_version']}; "
          f"load average {m['loadavg_at_start'][0]:.2f} -> {m['loadavg_at_end'][0]:.2f}")
    info = [b["extra_info"] for b in data["benchmarks"]]
    for header, holds, cells in TABLES:
        print("\n" + header)
        for e in filter(holds, info):
            print(f"| {cells(e)} |")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "results" / "latest.json")
