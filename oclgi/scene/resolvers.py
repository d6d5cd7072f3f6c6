"""Where trimesh finds the files a mesh file names (a glTF's ``.bin``
buffers, its images): beside it on disk, or beside it inside the zip.

Each resolver remembers the names it could not find (and a member refused
for its size), so that a failed load can say which file was missing:
trimesh itself goes on without it and then fails on the hole it left
(``'NoneType' object is not subscriptable``).
"""

from __future__ import annotations

import posixpath
from pathlib import Path

from trimesh.resolvers import FilePathResolver, Resolver

from ..errors import OclgiError
from .zip_reader import ZipReader


class FolderResolver(FilePathResolver):
    """Files in the mesh file's folder (and below it, never above)."""

    def __init__(self, path: Path):
        super().__init__(str(path))
        self.missing: list[str] = []
        self.refused = None

    def get(self, name: str):
        try:
            return super().get(name)
        except (OSError, ValueError):
            self.missing.append(name)
            raise


class MemberResolver(Resolver):
    """Members of a zip in one folder of it, read within the zip's bound."""

    def __init__(self, reader: ZipReader, folder: str):
        self.reader, self.folder = reader, folder
        self.missing: list[str] = []
        self.refused: OclgiError | None = None

    def _member(self, name: str) -> str:
        return posixpath.normpath(posixpath.join(self.folder, name.strip())).lstrip("/")

    def get(self, name: str) -> bytes:
        member = self._member(name)
        if member not in self.reader.names():
            self.missing.append(name)
            raise FileNotFoundError(name)
        try:
            return self.reader.read(member)
        except OclgiError as exc:  # trimesh swallows it; the load reports it
            self.refused = exc
            raise

    def keys(self):
        return [posixpath.relpath(n, self.folder or ".") for n in self.reader.names()]

    def namespaced(self, namespace: str) -> MemberResolver:
        return MemberResolver(self.reader, posixpath.join(self.folder, namespace))

    def write(self, name: str, data):
        raise OSError(f"cannot write {name!r} into a zip being read")
