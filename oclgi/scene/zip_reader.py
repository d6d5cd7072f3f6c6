"""Reading members of a mesh zip with a bound on what they inflate to.

A few megabytes of zip can inflate to gigabytes (a zip bomb), so every
member is checked against what is left of ``MAX_INFLATED`` before it is
inflated: by the size its header declares, then by a read that stops one
byte past that size, so a header that lies cannot make oclgi hold more.
The bound is for all members read from one zip together (the mesh, its
material libraries, a glTF's buffers).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from ..errors import OclgiError

# What one zip's members may inflate to, together: far above any scene
# oclgi renders (Sponza inflates to 20 MB), far below what a machine holds.
MAX_INFLATED = 1 << 30


def _size(n: int) -> str:
    return f"{n / (1 << 20):.1f} MiB" if n >= 1 << 20 else f"{n} bytes"


class ZipReader:
    """The members of an open zip, read within one shared bound."""

    def __init__(self, path: Path, archive: zipfile.ZipFile):
        self.path, self.archive = path, archive
        self.left = MAX_INFLATED

    def names(self) -> list[str]:
        return self.archive.namelist()

    def read(self, name: str) -> bytes:
        info = self.archive.getinfo(name)
        if info.file_size > self.left:
            left = "" if self.left == MAX_INFLATED else f"{_size(self.left)} left of the "
            raise OclgiError(f"{self.path}: member {name!r} inflates to {_size(info.file_size)}, more than "
                             f"the {left}{_size(MAX_INFLATED)} oclgi reads from one zip")
        with self.archive.open(info) as f:
            data = f.read(info.file_size + 1)
        if len(data) > info.file_size:
            raise OclgiError(f"{self.path}: member {name!r} inflates past the {_size(info.file_size)} "
                             "its header declares")
        self.left -= len(data)
        return data
