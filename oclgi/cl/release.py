"""Freeing a closed session's device memory now, not when Python collects it.

A session owns buffers through its store, estimators, view and pose; an
interactive server opens and closes sessions as tabs come and go, and the
device's memory (host memory on a CPU device) must come back when a tab
closes, whatever still refers to the session object. ``release`` walks the
attributes of oclgi's own objects from the given roots and releases every
OpenCL buffer it meets, except those of the objects that sessions share
(the engine and its compiled scene, marked ``shared_by_sessions``), which
are neither entered nor released even where a session's object holds one
of their buffers.

A released buffer must not be used again (pyopencl does not check, and the
driver may crash): the session drops its references as it closes.
"""

from __future__ import annotations

import pyopencl as cl


def _walk(roots):
    """(buffers reachable from roots, buffers held by shared objects)."""
    seen: set[int] = set()
    found, shared = {}, set()
    stack = list(roots)
    while stack:
        obj = stack.pop()
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, cl.MemoryObjectHolder):
            found[id(obj)] = obj
        elif isinstance(obj, (list, tuple, set, frozenset)):
            stack.extend(obj)
        elif isinstance(obj, dict):
            stack.extend(obj.values())
        elif (getattr(type(obj), "__module__", "") or "").startswith("oclgi") and hasattr(obj, "__dict__"):
            if getattr(obj, "shared_by_sessions", False):
                shared.update(id(v) for v in vars(obj).values() if isinstance(v, cl.MemoryObjectHolder))
            else:
                stack.extend(vars(obj).values())
    return found, shared


def release(*roots, keep=()) -> set[int]:
    """Release every buffer reachable from ``roots`` but the shared objects'
    and those reachable from ``keep`` (what still uses them: a store resized
    from the one released shares some of its buffers); their ids."""
    found, shared = _walk(roots)
    if keep:
        kept, kept_shared = _walk(keep)
        shared = shared | set(kept) | kept_shared
    done = set()
    for key, buf in found.items():
        if key not in shared:
            buf.release()
            done.add(key)
    return done
