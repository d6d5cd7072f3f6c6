"""trimesh's failures in plain words.

trimesh raises whatever its parsers hit on a malformed file: an empty
AssertionError, ``KeyError: 'fuble'``, an IndexError deep in numpy. None of
that tells a user what is wrong with their file, so only trimesh's own
messages (a ValueError or NameError its own code raised, in words) and a
JSON parser's are passed on; everything else reads as a malformed file. A missing optional package is
named, with how to get it.
"""

from __future__ import annotations

import json
import traceback

# trimesh's optional packages that the formats oclgi reads may need, by
# module, and the package to install for each. setup.cfg installs
# charset-normalizer with oclgi (plain STL and OFF files need it when they
# are not UTF-8); DracoPy only Draco-compressed glTF needs, and it is large.
PACKAGES = {"charset_normalizer": "charset-normalizer", "DracoPy": "DracoPy"}


def _raised_by_trimesh(exc: BaseException) -> bool:
    """Raised by a ``raise`` of trimesh's own (its message was written for
    people), not by numpy or Python inside a line of trimesh's."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return False
    last = frames[-1]
    return ("trimesh" in last.filename.replace("\\", "/").split("/")
            and (last.line or "").lstrip().startswith("raise"))


def trimesh_problem(exc: BaseException, missing: list[str]) -> str:
    """What is wrong with the file, as one short phrase."""
    if isinstance(exc, ImportError) and exc.name:
        module = exc.name.split(".")[0]
        package = PACKAGES.get(module, module)
        return (f"reading it needs the Python package {package!r}, which is not installed "
                f"(pip install {package})")
    if missing:
        return f"the file it names {missing[0]!r} is missing beside it"
    if isinstance(exc, json.JSONDecodeError):
        return f"its JSON is malformed ({exc.msg} at character {exc.pos})"
    text = " ".join(str(exc).split()).rstrip("!.")
    if isinstance(exc, (ValueError, NameError)) and text and _raised_by_trimesh(exc) and len(text) < 200:
        return f"it is malformed ({text})"
    return "it is malformed or uses a part of the format oclgi does not read"
