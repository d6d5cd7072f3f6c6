"""An animation's frames as one video file: GIF through Pillow, MP4 (H.264)
through imageio's ffmpeg plugin; both come with ``pip install 'oclgi[video]'``.

The file is written under a temporary name and renamed into place when it
is complete (oclgi/io.py), as every other output. H.264 in the yuv420p
pixels every player reads halves the colour resolution, so an MP4's width
and height must be even: a frame of odd size gets its last column or row
repeated once (ffmpeg itself refuses odd sizes with an error about the
encoder, not the image).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import OclgiError

SUFFIXES = (".gif", ".mp4")
INSTALL = "pip install 'oclgi[video]'"


def check(path: Path) -> None:
    """Refuse a video path oclgi cannot write, before any work: the suffix,
    and the library that writes it."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise OclgiError(f"{path}: a video must end in .gif or .mp4")
    try:
        if suffix == ".gif":
            import PIL.Image  # noqa: F401
        else:
            import imageio.v3  # noqa: F401
            import imageio_ffmpeg  # noqa: F401
    except ImportError:
        lib = "Pillow" if suffix == ".gif" else "imageio with its ffmpeg plugin"
        raise OclgiError(f"{path}: writing {suffix[1:].upper()} needs {lib}: {INSTALL}") from None


def _rgb(pixels: np.ndarray) -> np.ndarray:
    """RGBA frames over black (the background is transparent in the PNGs)."""
    a = pixels[..., 3:4].astype(np.uint16)
    return (pixels[..., :3].astype(np.uint16) * a // 255).astype(np.uint8)


def _even(frame: np.ndarray) -> np.ndarray:
    """The frame with its last column and row repeated where its width or height is odd."""
    h, w = frame.shape[:2]
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def write_video(path: Path, frames: list, fps: float) -> Path:
    """``frames``: (H, W, 4) uint8 arrays, in order."""
    from .io import atomic_path

    path = Path(path)
    check(path)
    if not frames:
        raise OclgiError(f"{path}: no frames")
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".gif":
            from PIL import Image

            images = [Image.fromarray(_rgb(f)) for f in frames]
            images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                           duration=round(1000 / fps), loop=0)
        else:
            import imageio.v3 as iio

            iio.imwrite(tmp, np.stack([_even(_rgb(f)) for f in frames]), extension=".mp4", fps=fps,
                        codec="libx264", macro_block_size=1)
    return path
