"""Writing results: images through OpenImageIO, arrays as .npy or .csv.

Every file is written under a temporary name in the target folder (see
:mod:`oclgi.tempfiles`), flushed to disk, checked (an image is read back
whole) and only then renamed into place: a failed, interrupted or
terminated run, or a full disk, never leaves a partial output file (nor the
temporary one). :func:`write_images` writes several files all or nothing (a
render's EXR and PNG). Every image carries the ``Software`` attribute
``oclgi``, so a later run can tell its own earlier output from a user's file.
"""

from __future__ import annotations

import errno
import io
import os
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from . import tempfiles
from .errors import OclgiError

SOFTWARE = "oclgi"


def _reason(exc: OSError) -> str:
    """An OS error in plain words: "no space left on device"."""
    text = exc.strerror or str(exc)
    return text[:1].lower() + text[1:]


def _existing_ancestor(path: Path) -> Path:
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


def check_output(path) -> Path:
    """Fail early (before any work) when ``path`` can never be written: a
    folder, a parent that is a file, a folder (or its nearest existing
    ancestor) where no file can be created, or an existing read-only file."""
    path = Path(path)
    if path.is_dir():
        raise OclgiError(f"cannot write {path}: it is a folder")
    parent = _existing_ancestor(path)
    if parent.exists() and not parent.is_dir():
        raise OclgiError(f"cannot write {path}: {parent} is not a folder")
    if path.exists() and not os.access(path, os.W_OK):
        raise OclgiError(f"cannot write {path}: the file is read-only")
    # Creating a file is the only test that also holds for root (who passes
    # every permission check) and read-only or virtual file systems.
    try:
        probe = tempfiles.create_file(parent / path.name, ".probe")
    except OSError as exc:
        raise OclgiError(f"cannot write {path}: {_reason(exc)} (in {parent})") from None
    tempfiles.remove(probe)
    return path


def check_not_input(outputs, inputs: dict) -> None:
    """Refuse (before any work) an output that is one of the run's input files.

    ``inputs`` maps a file to what it is ("the scene file"); files that do not
    exist are ignored (an output can only overwrite what exists).
    """
    for out in map(Path, outputs):
        if not out.exists():
            continue
        for inp, what in inputs.items():
            try:
                same = Path(inp).exists() and os.path.samefile(out, inp)
            except OSError:
                same = False
            if same:
                raise OclgiError(f"cannot write {out}: it is {what}, which the output would replace")


def is_oclgi_image(path) -> bool:
    """Whether ``path`` is an image oclgi wrote (its Software attribute)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()  # clear it: not an image is a plain "no"
        return False
    try:
        return inp.spec().get_string_attribute("Software") == SOFTWARE
    finally:
        inp.close()


def _sync(tmp: Path, path: Path, flush: bool = True) -> None:
    """Flush ``tmp`` to disk and refuse an empty one: a full disk may only
    show here (network file systems report it at the flush)."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        if flush:
            os.fsync(fd)
        size = os.fstat(fd).st_size
    finally:
        os.close(fd)
    if size == 0:
        raise OclgiError(f"cannot write {path}: nothing reached the disk (is it full?)")


def _sync_folder(folder: Path) -> None:
    # The rename itself is durable only once the folder is flushed.
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems do not sync folders; the file itself is synced
    finally:
        os.close(fd)


@contextmanager
def atomic_paths(paths, sync: bool = True):
    """Yield temporary paths beside ``paths`` (same suffixes); when the block
    succeeds, each is flushed and checked, and only then are all renamed into
    place: all or nothing. OS errors become an :class:`OclgiError`.

    ``sync=False`` leaves the flush to the caller: files made inside a
    :func:`staged_folder`, which flushes them all once at its end.
    """
    paths = [Path(p) for p in paths]
    for path in paths:
        check_output(path)
    tempfiles.install_signal_cleanup()
    temps = []
    current = paths[0] if paths else None
    try:
        for path in paths:
            current = path
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise OclgiError(f"cannot create output folder {path.parent}: {_reason(exc)}") from None
            tempfiles.remove_stale(path.parent)
            temps.append(tempfiles.create_file(path))
        yield list(temps)
        for tmp, path in zip(temps, paths):
            current = path
            _sync(tmp, path, sync)
        for tmp, path in zip(temps, paths):
            current = path
            os.replace(tmp, path)
            tempfiles.release(tmp)
        for folder in {p.parent for p in paths} if sync else ():
            _sync_folder(folder)
    except BaseException as exc:
        for tmp in temps:
            tempfiles.remove(tmp)
        if isinstance(exc, OSError):
            raise OclgiError(f"cannot write {current}: {_reason(exc)}") from None
        raise


@contextmanager
def atomic_path(path: Path, sync: bool = True):
    """:func:`atomic_paths` for one file: yield its temporary path."""
    with atomic_paths([path], sync) as (tmp,):
        yield tmp


@contextmanager
def staged_folder(path):
    """Yield a temporary folder for the files of the folder ``path``; when
    the block succeeds, move what it holds into ``path``, else remove it: a
    failed run adds nothing to ``path``.

    A missing ``path`` is staged beside it and renamed into place whole; an
    existing one is staged inside it (hidden), which needs no right to write
    its parent.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OclgiError(f"{path}: exists and is not a folder")
    check_output(path / "frame")  # the folder (or where it will be) takes files
    tempfiles.install_signal_cleanup()
    existed = path.is_dir()
    beside = path / path.name if existed else path
    try:
        beside.parent.mkdir(parents=True, exist_ok=True)
        tempfiles.remove_stale(beside.parent)
        tempfiles.remove_stale(path.parent)  # an earlier run's stage beside it
        stage = tempfiles.create_folder(beside)
    except OSError as exc:
        raise OclgiError(f"cannot write {path}: {_reason(exc)}") from None
    try:
        yield stage
        # One flush of everything, rather than one per file as it was made.
        for entry in stage.iterdir():
            if entry.is_file():
                _sync(entry, path / entry.name)
        _sync_folder(stage)
        if not existed:
            os.rename(stage, path)  # all at once
        else:
            for entry in sorted(stage.iterdir()):
                os.replace(entry, path / entry.name)
            stage.rmdir()
        tempfiles.release(stage)
        _sync_folder(path.parent if not existed else path)
    except BaseException as exc:
        tempfiles.remove(stage)
        if isinstance(exc, OSError):
            raise OclgiError(f"cannot write {path}: {_reason(exc)}") from None
        raise


def _oiio_error(text: str, tmp: Path, path: Path) -> str:
    # The library names the temporary file; the user knows only the output.
    return _one_line(str(text).replace(str(tmp), str(path))) or "the image library gave no reason"


def _one_line(text: str) -> str:
    return " ".join(part.strip() for part in text.splitlines() if part.strip())


def write_image_file(tmp: Path, path: Path, pixels: np.ndarray, metadata: dict | None = None,
                     channels: list | None = None) -> None:
    """Write an image to ``tmp`` (a temporary name from :func:`atomic_path`; ``path``
    names it in errors): the one OpenImageIO writer of every image oclgi makes.

    The file is read back whole before this returns: some writers (PNG's)
    report success for a file the disk had no room for. (:func:`atomic_paths`
    flushes it before the rename.)
    """
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    fmt = oiio.FLOAT if pixels.dtype == np.float32 else oiio.UINT8
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise OclgiError(f"cannot write {path}: {_oiio_error(oiio.geterror(), tmp, path)}")
    spec = oiio.ImageSpec(w, h, c, fmt)
    if channels is not None:  # named channels: an EXR's layers (R, G, B, then irradiance.R, ...)
        if len(channels) != c:
            raise OclgiError(f"cannot write {path}: {len(channels)} channel names for {c} channels")
        spec.channelnames = tuple(channels)
    # No time stamp (OpenEXR's writer adds one unless told otherwise): the
    # same run gives the same bytes, so renders can be compared with cmp.
    spec.attribute("DateTime", "")
    spec.attribute("Software", SOFTWARE)
    for key, value in (metadata or {}).items():  # str, int or float attributes
        spec.attribute(key, value)
    if path.suffix.lower() == ".exr":
        spec.attribute("compression", "zip")
    ok = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(pixels))
    err = out.geterror()
    closed = out.close()
    if not ok or not closed:
        raise OclgiError(f"cannot write {path}: {_oiio_error(err or out.geterror(), tmp, path)}")
    _check_readable(tmp, path, (h, w, c))


def _check_readable(tmp: Path, path: Path, shape) -> None:
    import OpenImageIO as oiio

    back = None
    with _quiet_stderr():  # libpng prints its own complaint about a truncated file
        inp = oiio.ImageInput.open(str(tmp))
        if inp is not None:
            try:
                back = inp.read_image()
            finally:
                inp.close()
    oiio.geterror()  # the reason is the disk's, not the reader's
    if back is None or tuple(back.shape) != tuple(shape):
        raise OclgiError(f"cannot write {path}: the file on disk is incomplete (is the disk full?)")


@contextmanager
def _quiet_stderr():
    """Silence what C libraries print on file descriptor 2 meanwhile."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def write_image(path, pixels: np.ndarray) -> Path:
    """Write an (H, W, C) image: float32 for EXR (linear), uint8 for PNG."""
    path = Path(path)
    with atomic_path(path) as tmp:
        write_image_file(tmp, path, pixels)
    return path


def write_images(images: dict, sync: bool = True, metadata: dict | None = None,
                 channels: dict | None = None) -> list[Path]:
    """Write several images ``{path: pixels}``, all or nothing, each with
    the attributes ``metadata`` (a render's: how it was made); ``channels``:
    {path: channel names} for images with more than RGB(A).

    Every image is written to its temporary file and checked first; only
    when all are complete are they renamed into place. ``sync``: as for
    :func:`atomic_paths`.
    """
    paths = [Path(p) for p in images]
    with atomic_paths(paths, sync) as temps:
        for tmp, p, pixels in zip(temps, paths, images.values()):
            write_image_file(tmp, p, pixels, metadata, (channels or {}).get(p))
    return paths


def png_bytes(pixels: np.ndarray) -> bytes:
    """An (H, W, 4) uint8 RGBA image as PNG bytes, in memory (for notebooks:
    no file, no image library): one IDAT of unfiltered rows."""
    import struct
    import zlib

    a = np.ascontiguousarray(pixels, np.uint8)
    if a.ndim != 3 or a.shape[2] != 4:
        raise OclgiError(f"png_bytes: expected (H, W, 4) pixels, got shape {a.shape}")
    h, w = a.shape[:2]
    rows = np.concatenate([np.zeros((h, 1), np.uint8), a.reshape(h, w * 4)], axis=1)  # filter byte 0 per row

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)  # 8 bits, RGBA, deflate, no filter, no interlace
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
            + chunk(b"IEND", b""))


def read_csv(path, what: str, widths: tuple, columns: str) -> np.ndarray:
    """A table of numbers, the one CSV reader of the command line (points,
    keyframes): fields separated by commas (or whitespace); blank lines and
    lines starting with ``#`` skipped; a first line that is not numbers is a
    header; every row has the same number of fields, one of ``widths``. A
    malformed line is an error naming it and ``columns`` (what the fields are)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise OclgiError(f"{path}: not a text (CSV) file") from None
    except OSError as exc:
        raise OclgiError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    rows, first, width = [], True, None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = [x.strip() for x in line.split(",")] if "," in line else line.split()
        try:
            values = [float(x) for x in fields]
        except ValueError:
            if first and not any(_is_number(x) for x in fields):  # a header
                first = False
                continue
            want = width if width is not None else " or ".join(map(str, widths))
            raise OclgiError(f"{path}:{lineno}: expected {want} numbers ({columns}), got {line!r}") from None
        first = False
        if len(values) not in widths or (width is not None and len(values) != width):
            want = width if width is not None else " or ".join(map(str, widths))
            raise OclgiError(f"{path}:{lineno}: expected {want} columns ({columns}), got {len(values)}")
        width = len(values)
        rows.append(values)
    if not rows:
        raise OclgiError(f"{path}: no {what}")
    return np.array(rows, dtype=np.float64)


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def read_npy(path, what: str) -> np.ndarray:
    """A ``.npy`` array of real numbers (points, keyframes, a reference), the
    one reader of every .npy oclgi takes: the header's shape is checked
    against the file's size before numpy allocates it (a header may claim
    terabytes), and every failure names the file and ``what`` it was to hold."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            try:
                version = np.lib.format.read_magic(f)
                read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                               (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                if read_header is None:
                    raise ValueError(f"unknown .npy version {version}")
                shape, fortran, dtype = read_header(f)
            except ValueError as exc:
                raise OclgiError(f"{path}: not a .npy file of {what} ({exc})") from None
            if dtype.kind not in "iuf" or dtype.hasobject:
                raise OclgiError(f"{path}: expected {what} as numbers, got an array of {dtype}")
            count = int(np.prod(shape, dtype=object))  # exact: no overflow for any shape
            data = os.fstat(f.fileno()).st_size - f.tell()
            if count * dtype.itemsize != data:
                raise OclgiError(f"{path}: its header declares shape {shape} ({count * dtype.itemsize:,} bytes), "
                                 f"the file holds {data:,} bytes of data")
            a = np.fromfile(f, dtype=dtype, count=count).reshape(shape, order="F" if fortran else "C")
    except OSError as exc:
        raise OclgiError(f"cannot read {path}: {exc.strerror or exc}") from None
    return a


def read_image(path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OclgiError(f"cannot read {path}: {oiio.geterror()}")
    try:
        return inp.read_image()
    finally:
        inp.close()


def write_bytes(tmp: Path, data: bytes) -> None:
    """Write ``data`` to ``tmp`` and check that every byte reached the file.

    The data is made in memory first (it is small: one row per point or
    frame) so that a full disk surfaces as the OS's own error here.
    """
    with open(tmp, "wb") as f:
        f.write(data)
    if os.stat(tmp).st_size != len(data):
        raise OSError(errno.EIO, "the file on disk is shorter than what was written")


def write_array(path, values: np.ndarray, points=None, columns=("E_r", "E_g", "E_b")) -> Path:
    """Irradiance per point: ``.npy`` (n, 3) float64 (or (n,) for one
    column), or ``.csv`` with the points' columns, then ``columns``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv"):
        raise OclgiError(f"{path}: output must end in .npy or .csv")
    values = np.asarray(values, dtype=np.float64)
    with atomic_path(path) as tmp:
        buf = io.BytesIO()
        if suffix == ".npy":
            np.save(buf, values)
        else:
            cols = list(columns)
            data = values.reshape(len(values), -1)
            if points is not None:
                cols = ["x", "y", "z", "nx", "ny", "nz"] + cols
                data = np.hstack([points.positions[:, :3], points.normals[:, :3], data])
            np.savetxt(buf, data, delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
        write_bytes(tmp, buf.getvalue())
    return path


def write_array_text(path, columns: list[str], rows, sync: bool = True) -> Path:
    """A CSV table with a header line (e.g. a per-frame timing log); ``sync``:
    as for :func:`atomic_paths`."""
    path = Path(path)
    lines = [",".join(columns)] + [
        ",".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in r) for r in rows]
    data = ("\n".join(lines) + "\n").encode()
    with atomic_path(path, sync) as tmp:
        write_bytes(tmp, data)
    return path
