"""The constants host and kernels share are defined once (oclgi/cl/constants.py).

Every build gets them as -D defines; kernels/constants.h stops a build that
lacks one, and no kernel file keeps a copy of its own. A probe built with the
program cache's options reports what the kernels see.
"""

import re

import numpy as np
import pyopencl as cl
import pytest

from oclgi.cl import constants
from oclgi.cl.programs import ProgramCache, kernel_dir, programs
from oclgi.estimators.photon_map import DEFAULT_K

SHARED = {f"OCLGI_{name.upper()}" for name in constants.DEFINES}
# Defines a driver sets per program, and names that are no define of the host's.
PER_PROGRAM = {"OCLGI_KNN_K", "OCLGI_COUNT_WORK", "OCLGI_BVH_COUNT", "OCLGI_CONSISTENT_SPAN",
               "OCLGI_SCENE_FLAT_INSTANCES"}
PER_DEVICE = {"OCLGI_PREFETCH_AHEAD"}  # set by the program cache from the device (oclgi/cl/programs.py)
KERNEL_ONLY = {"OCLGI_PI", "OCLGI_FIXED_ONE"}  # FIXED_ONE: derived from OCLGI_FIXED_BITS in constants.h


def _sources():
    return {p.name: re.sub(r"/\*.*?\*/", "", p.read_text(), flags=re.DOTALL)
            for p in sorted(kernel_dir().iterdir()) if p.suffix in (".cl", ".h")}


def test_constants_h_requires_every_shared_constant():
    src = (kernel_dir() / "constants.h").read_text()
    required = set(re.findall(r"defined\((OCLGI_\w+)\)", src))
    assert required == SHARED


def test_no_kernel_file_defines_a_shared_constant():
    copies = [f"{name}: {m}" for name, src in _sources().items()
              for m in re.findall(r"#\s*define\s+(OCLGI_\w+)", src) if m in SHARED]
    assert not copies, "the host defines these (oclgi/cl/constants.py):\n" + "\n".join(copies)


def test_every_oclgi_name_in_the_kernels_is_known():
    used = {m for src in _sources().values() for m in re.findall(r"\bOCLGI_\w+", src)}
    guards = {m for m in used if m.endswith("_H")}
    assert used - guards - SHARED - PER_PROGRAM - PER_DEVICE - KERNEL_ONLY == set()


def test_build_without_the_constants_stops(cl_env):
    ctx, _ = cl_env
    src = '#include "oclgi_types.h"\n__kernel void k(__global int *o) { o[0] = 0; }\n'
    with pytest.raises(cl.RuntimeError, match="shared constants are not defined"):
        cl.Program(ctx, src).build(options=["-I", str(kernel_dir())])


PROBE = """
#include "constants.h"
__kernel void constants_probe(__global ulong *u, __global float *f)
{
    int i = 0;
    u[i++] = OCLGI_LANES; u[i++] = OCLGI_BVH_STACK_SIZE; u[i++] = OCLGI_BOX_BVH_STACK;
    u[i++] = OCLGI_POINT_BVH_STACK; u[i++] = OCLGI_FIXED_BITS; u[i++] = OCLGI_SC_MAX_LEVELS;
    u[i++] = OCLGI_RADIX_BITS; u[i++] = OCLGI_CELL_OUTSIDE_BIT; u[i++] = OCLGI_EMITTER_TRIANGLE;
    u[i++] = OCLGI_EMITTER_POINT; u[i++] = OCLGI_EMITTER_SPOT; u[i++] = OCLGI_EMITTER_SUN;
    u[i++] = OCLGI_EMITTER_SKY; u[i++] = OCLGI_EMITTER_ENVMAP;
    u[i++] = OCLGI_BSDF_DIFFUSE; u[i++] = OCLGI_BSDF_PHONG; u[i++] = OCLGI_BSDF_MIRROR;
    u[i++] = OCLGI_BSDF_DIELECTRIC; u[i++] = OCLGI_BSDF_CONDUCTOR; u[i++] = OCLGI_BSDF_ROUGH_DIELECTRIC;
    u[i++] = OCLGI_MATERIAL_TWOSIDED; u[i++] = OCLGI_MATERIAL_DELTA; u[i++] = OCLGI_CAMERA_MAX_DEPTH;
    u[i++] = OCLGI_MATERIAL_VERTEX_COLOUR; u[i++] = OCLGI_EMITTER_IES; u[i++] = OCLGI_VIEW_SRGB;
    u[i++] = OCLGI_VIEW_AGX; u[i++] = OCLGI_VIEW_FILMIC; u[i++] = OCLGI_BOX_LEAF_BITS;
    u[i++] = OCLGI_BOX_WIDE_STACK; u[i++] = OCLGI_SAH_BINS;
    f[0] = OCLGI_FRONT_COS_EPS;
    f[1] = (float)OCLGI_SC_MU;
}
"""
INTEGERS = ("LANES", "BVH_STACK_SIZE", "BOX_BVH_STACK", "POINT_BVH_STACK", "FIXED_BITS", "SC_MAX_LEVELS",
            "RADIX_BITS", "CELL_OUTSIDE_BIT",
            "EMITTER_TRIANGLE", "EMITTER_POINT", "EMITTER_SPOT", "EMITTER_SUN", "EMITTER_SKY", "EMITTER_ENVMAP",
            "BSDF_DIFFUSE", "BSDF_PHONG", "BSDF_MIRROR", "BSDF_DIELECTRIC", "BSDF_CONDUCTOR", "BSDF_ROUGH_DIELECTRIC",
            "MATERIAL_TWOSIDED", "MATERIAL_DELTA", "CAMERA_MAX_DEPTH",
            "MATERIAL_VERTEX_COLOUR", "EMITTER_IES", "VIEW_SRGB", "VIEW_AGX", "VIEW_FILMIC", "BOX_LEAF_BITS",
            "BOX_WIDE_STACK", "SAH_BINS")


def test_kernels_see_the_host_values(cl_env):
    ctx, queue = cl_env
    assert set(INTEGERS) | {"FRONT_COS_EPS", "SC_MU"} == {n.upper() for n in constants.DEFINES}
    options = ProgramCache(ctx).options(())
    prog = cl.Program(ctx, PROBE).build(options=options)
    mf = cl.mem_flags
    u = cl.Buffer(ctx, mf.WRITE_ONLY, 8 * len(INTEGERS))
    f = cl.Buffer(ctx, mf.WRITE_ONLY, 8)
    prog.constants_probe(queue, (1,), None, u, f)
    got_u = np.empty(len(INTEGERS), np.uint64)
    got_f = np.empty(2, np.float32)
    cl.enqueue_copy(queue, got_u, u)
    cl.enqueue_copy(queue, got_f, f)
    assert [int(v) for v in got_u] == [getattr(constants, n) for n in INTEGERS]
    assert got_f[0] == np.float32(constants.FRONT_COS_EPS)
    assert got_f[1] == np.float32(constants.SC_MU)


def test_a_program_cannot_override_a_shared_constant(cl_env):
    with pytest.raises(ValueError, match="lanes"):
        programs(cl_env[0]).get("detp", lanes=4)


def test_point_index_default_k_is_the_estimators():
    """point_index.h keeps a K for builds of the file alone; the host always sets it."""
    m = re.search(r"#define\s+OCLGI_KNN_K\s+(\d+)", (kernel_dir() / "point_index.h").read_text())
    assert m and int(m.group(1)) == DEFAULT_K
