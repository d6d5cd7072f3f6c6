"""Struct layouts shared by host and kernels agree.

``kernels/layout_probe.cl`` writes, for every struct of
``oclgi.cl.layout.STRUCTS`` in that dict's order, its sizeof and then the
offsetof of each field in the numpy dtype's field order, and finally -1. The
numbers must equal the numpy dtypes' itemsize and field offsets.
"""

import re

import numpy as np
import pyopencl as cl
import pytest

from oclgi.cl import layout
from oclgi.cl.programs import kernel_dir, programs


def _expected():
    """[(struct, what, value)] in probe order: size, then each field's offset."""
    out = []
    for name, dt in layout.STRUCTS.items():
        out.append((name, "sizeof", dt.itemsize))
        for field in dt.names:
            out.append((name, f"offsetof {field}", dt.fields[field][1]))
    return out


@pytest.fixture(scope="module")
def probe_result(cl_env):
    """The probe's output, or the build error (reported by each test as a failure)."""
    try:
        return _probe(*cl_env)
    except RuntimeError as exc:
        return exc


def _output(probe_result):
    """The probe's numbers; a build error fails the calling test (not its setup)."""
    if isinstance(probe_result, Exception):
        errors = [line.strip() for line in str(probe_result).splitlines() if "error" in line.lower()]
        pytest.fail("layout_probe.cl does not build:\n" + "\n".join(errors[:5]), pytrace=False)
    return probe_result


def _probe(ctx, queue):
    prog = programs(ctx).get("layout_probe")
    n = len(_expected()) + 16
    out = np.full(n, -2, np.int32)
    buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=out)
    prog.layout_probe(queue, (1,), None, buf)
    cl.enqueue_copy(queue, out, buf)
    queue.finish()
    return out


def test_probe_ends_where_layout_py_ends(probe_result):
    probed = _output(probe_result)
    expected = _expected()
    end = int(np.argmax(probed == -1)) if (probed == -1).any() else None
    assert end is not None, f"no end marker in the probe output {probed.tolist()}"
    assert end == len(expected), (
        f"layout_probe.cl reports {end} numbers, layout.py's STRUCTS describe {len(expected)}: "
        "a struct or field was added on one side only")


def test_sizes_and_offsets_match(probe_result):
    probed = _output(probe_result)
    expected = _expected()
    mismatches = [f"{s}.{what}: kernel {int(got)}, numpy {want}"
                  for (s, what, want), got in zip(expected, probed) if int(got) != want]
    assert not mismatches, "\n".join(mismatches)


@pytest.mark.parametrize("name", list(layout.STRUCTS))
def test_struct_is_16_byte_multiple(name):
    # The structs are arrays on the device: keep them float4-aligned.
    assert layout.STRUCTS[name].itemsize % 16 == 0


def test_probe_covers_every_field_in_order():
    """The probe source names the same structs and fields, in the same order.

    The kernel output already checks the numbers; this catches a field that
    is renamed on one side (same offset, different meaning).
    """
    src = (kernel_dir() / "layout_probe.cl").read_text()
    body = src[src.index("__kernel"):]
    calls = re.findall(r"\b(SIZE|OFF)\((\w+)(?:,\s*(\w+))?\)", body)
    got = [(s, "sizeof" if kind == "SIZE" else f"offsetof {f}") for kind, s, f in calls]
    assert got == [(s, what) for s, what, _ in _expected()]


def test_header_declares_every_struct_with_layout_py_fields():
    """oclgi_types.h declares each struct with the dtype's fields, in order."""
    src = (kernel_dir() / "oclgi_types.h").read_text()
    src = re.sub(r"/\*.*?\*/", "", src, flags=re.S)
    for name, dt in layout.STRUCTS.items():
        m = re.search(r"typedef\s+struct\s*\{([^}]*)\}\s*" + name + r"\s*;", src)
        assert m, f"{name} not declared in oclgi_types.h"
        fields = re.findall(r"\b(\w+)\s*(?:\[\s*\d+\s*\])?\s*;", m.group(1))
        assert fields == list(dt.names), name


def test_wide_node_is_32_byte_aligned(probe_result):
    """BvhNode8's float8 fields are one AVX register each: the device aligns
    the struct to 32 bytes, and its size keeps every record of an array so."""
    probed = _output(probe_result)
    end = int(np.argmax(probed == -1))
    assert probed[end + 1] == 32
    assert layout.BvhNode8.itemsize % 32 == 0
    # instance boxes follow the Instance records in one buffer, from a 32-byte boundary
    assert probed[end + 2] == 32 and layout.InstanceBoxes.itemsize % 32 == 0
