"""Writing a scene dict as TOML text (the standard library reads TOML, it
does not write it). Any value hypothesis draws gets written, NaN, infinities
and integers past 64 bits included, so the reader sees what a user could
type; a value TOML cannot hold (None) is written as a string."""

from __future__ import annotations

import json
import math
import re

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def key(k) -> str:
    k = str(k)
    return k if _BARE.fullmatch(k) else _string(k)


def _string(s: str) -> str:
    # TOML's basic strings take JSON's escapes, but no raw DEL
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + "}"
    return _string(repr(v))


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(desc: dict) -> str:
    lines, tables = [], []
    for k, v in desc.items():
        if isinstance(v, dict) or _is_tables(v):
            tables.append((k, v))
        else:
            lines.append(f"{key(k)} = {value(v)}")
    for k, v in tables:
        for table in [v] if isinstance(v, dict) else v:
            lines.append("")
            lines.append(f"[{key(k)}]" if isinstance(v, dict) else f"[[{key(k)}]]")
            lines += [f"{key(a)} = {value(b)}" for a, b in table.items()]
    return "\n".join(lines) + "\n"
