#!/usr/bin/env python3
"""Prints docs/configuration.md from idl/densemap.proto: every message the server config
reaches, every field with its type, default and the schema's own comment, so the reference
cannot drift from the schema. Usage:
  scripts/config-reference.py            # print the page
  scripts/config-reference.py --check    # exit 1 when docs/configuration.md differs
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
PROTOS = [ROOT / "idl" / "densemap.proto", ROOT / "idl" / "snapshot.proto"]
PAGE = ROOT / "docs" / "configuration.md"

FIELD = re.compile(
    r"^\s*(optional|repeated|required)\s+(\w+)\s+(\w+)\s*=\s*\d+\s*(\[default\s*=\s*([^\]]+)\])?\s*;"
    r"\s*(//\s*(.*))?$")
MESSAGE = re.compile(r"^\s*message\s+(\w+)\s*\{")
COMMENT = re.compile(r"^\s*//\s?(.*)$")

HEADER = """# Configuration reference

The server reads one file in protobuf text format (`densemap-server --config FILE`); its
schema is `idl/densemap.proto`. Unknown fields, wrong types and values out of range stop the
server with the file, the line and the reason (exit 2); `densemap-server --check-config FILE`
checks a file without starting anything. `config/densemap.textproto` is a complete example with
every default written out.

This page is printed from the schema by `scripts/config-reference.py` (a test fails when it is
out of date). Absent fields take the default shown; sizes are in the unit their name ends with.

```
map { kind: "akimap_rays" resolution_m: 0.1 max_range_m: 30 keep_radius_m: 60 }
pipeline { threads: 4 }
snapshot { path: "/var/lib/densemap/densemap.dmap" autosave_period_s: 30 }
ros2 { enabled: true clouds: "/points" world_frame: "map" }
```
"""


def parse(path):
    """Returns {message: (comment lines, [(label, type, name, default, comment)])}."""
    messages, order = {}, []
    pending, current, depth = [], None, 0
    for line in path.read_text().splitlines():
        m = MESSAGE.match(line)
        if m and depth == 0:
            current = m.group(1)
            messages[current] = (pending, [])
            order.append(current)
            pending, depth = [], 1
            continue
        if current is None:
            c = COMMENT.match(line)
            pending = pending + [c.group(1)] if c else []
            continue
        depth += line.count("{") - line.count("}")
        if depth <= 0:
            current, pending, depth = None, [], 0
            continue
        c = COMMENT.match(line)
        if c:
            pending.append(c.group(1))
            continue
        f = FIELD.match(line)
        if f:
            text = " ".join(pending + ([f.group(7)] if f.group(7) else []))
            default = f.group(5).strip() if f.group(5) else ""
            messages[current][1].append((f.group(1), f.group(2), f.group(3), default, text))
        pending = []
    return messages, order


def main():
    messages, order = {}, []
    for proto in PROTOS:
        m, o = parse(proto)
        messages.update(m)
        order += o
    root = "ServerConfig"
    out = [HEADER]
    # The top-level blocks, then every message they reach, in schema order.
    # Each message the root reaches, named by the config path of the field that reaches it.
    paths, queue = {root: ""}, [root]
    while queue:
        name = queue.pop(0)
        for _, ftype, fname, _, _ in messages[name][1]:
            if ftype in messages and ftype not in paths:
                paths[ftype] = f"{paths[name]}.{fname}" if paths[name] else fname
                queue.append(ftype)
    for name in [root] + [n for n in order if n in paths and n != root]:
        comment, fields = messages[name]
        title = f"`{paths[name]}` ({name})" if paths[name] else f"Top level ({name})"
        out.append(f"## {title}\n")
        if comment:
            out.append(" ".join(comment) + "\n")
        out.append("| field | type | default | meaning |")
        out.append("|---|---|---|---|")
        for label, ftype, fname, default, text in fields:
            kind = f"repeated {ftype}" if label == "repeated" else ftype
            shown = f"`{default}`" if default else ("-" if ftype in messages else "unset")
            out.append(f"| `{fname}` | {kind} | {shown} | {text.replace('|', '/')} |")
        out.append("")
    page = "\n".join(out).rstrip() + "\n"
    if len(sys.argv) > 1 and sys.argv[1] == "--check":
        if not PAGE.exists() or PAGE.read_text() != page:
            sys.stderr.write("docs/configuration.md is out of date with idl/densemap.proto: "
                             "run scripts/config-reference.py > docs/configuration.md\n")
            return 1
        return 0
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
