#!/usr/bin/env python3
"""docs/service/api-reference.md from the comments of proto/radiosity/v1/*.proto.

Every service, RPC, message, field, enum and enum value with the comment written above it (or
after it on its line), in the order of the files. The protos are the source of truth; this page
is their rendering, and a test fails when it is out of date.

Usage: proto_reference.py --source DIR (--check | --write)
"""

import argparse
import os
import re
import sys

FILES = ["proto/radiosity/v1/service.proto", "proto/radiosity/v1/scene.proto"]
PAGE = "docs/service/api-reference.md"
SCOPE = re.compile(r"^(message|enum|service|oneof)\s+(\w+)\s*\{\s*(?://\s?(.*))?$")
RPC = re.compile(r"^rpc\s+(\w+)\s*\(\s*(stream\s+)?([\w.]+)\s*\)\s*returns\s*\(\s*(stream\s+)?"
                 r"([\w.]+)\s*\)\s*[;{]\s*(?://\s?(.*))?$")
FIELD = re.compile(r"^(optional\s+|repeated\s+)?(map\s*<[^>]+>|[\w.]+)\s+(\w+)\s*=\s*(\d+)\s*"
                   r"(\[[^\]]*\])?\s*;\s*(?://\s?(.*))?$")
VALUE = re.compile(r"^(\w+)\s*=\s*(-?\d+)\s*(\[[^\]]*\])?\s*;\s*(?://\s?(.*))?$")


class Scope:
    def __init__(self, kind, name, comment, parent):
        self.kind, self.name, self.comment, self.parent = kind, name, comment, parent
        self.items = []  # (kind, fields...)
        self.children = []

    def full_name(self):
        names, s = [], self
        while s is not None and s.kind != "file":
            if s.kind != "oneof":
                names.append(s.name)
            s = s.parent
        return ".".join(reversed(names))


def parse(path):
    root = Scope("file", os.path.basename(path), "", None)
    scope, pending = root, []
    for raw in open(path, encoding="utf-8"):
        line = raw.strip()
        if line.startswith("//"):
            pending.append(line[2:][1:] if line[2:3] == " " else line[2:])
            continue
        comment = " ".join(pending).strip()
        if not line:
            pending = []
            continue
        pending = []
        m = SCOPE.match(line)
        if m:
            child = Scope(m.group(1), m.group(2), " ".join(filter(None, [comment, m.group(3)])),
                          scope)
            scope.children.append(child)
            if m.group(1) == "oneof":
                scope.items.append(("oneof", child))
            scope = child
            continue
        if line.startswith("}"):
            scope = scope.parent or root
            continue
        m = RPC.match(line)
        if m:
            scope.items.append(("rpc", m.group(1), (m.group(2) or "") + m.group(3),
                                (m.group(4) or "") + m.group(5),
                                " ".join(filter(None, [comment, m.group(6)]))))
            continue
        m = FIELD.match(line)
        if m and scope.kind in ("message", "oneof"):
            label = (m.group(1) or "").strip()
            options = m.group(5) or ""
            note = " ".join(filter(None, [comment, m.group(6)]))
            if "deprecated = true" in options.replace(" ", " "):
                note = ("**Deprecated.** " + note).strip()
            target = scope
            oneof = scope.name if scope.kind == "oneof" else ""
            while target.kind == "oneof":
                target = target.parent
            target.items.append(("field", " ".join(filter(None, [label, m.group(2)])), m.group(3),
                                 int(m.group(4)), note, oneof))
            continue
        m = VALUE.match(line)
        if m and scope.kind == "enum":
            scope.items.append(("value", m.group(1), int(m.group(2)),
                                " ".join(filter(None, [comment, m.group(4)]))))
    return root


def cell(text):
    return text.replace("|", "\\|").replace("\n", " ") if text else ""


def render(source):
    out = ["# API reference", "",
           "Generated from the comments of " + ", ".join(
               f"[`{os.path.basename(f)}`](../../{f})" for f in FILES) +
           " by `tests/docs/proto_reference.py --write`; a test keeps it equal to the protos, which "
           "are the source of truth. The overview, conventions and examples are in "
           "[API](api.md).", ""]
    for f in FILES:
        root = parse(os.path.join(source, f))
        out += [f"## `{os.path.basename(f)}`", ""]

        def walk(scope, depth):
            for child in scope.children:
                if child.kind == "oneof":
                    continue
                heading = "#" * min(depth, 6)
                out.extend([f"{heading} {child.kind} `{child.full_name()}`", ""])
                if child.comment:
                    out.extend([child.comment, ""])
                rpcs = [i for i in child.items if i[0] == "rpc"]
                fields = [i for i in child.items if i[0] == "field"]
                values = [i for i in child.items if i[0] == "value"]
                if rpcs:
                    out.extend(["| RPC | request | response | description |", "| --- | --- | --- | --- |"])
                    out.extend([f"| `{r[1]}` | `{r[2]}` | `{r[3]}` | {cell(r[4])} |" for r in rpcs])
                    out.append("")
                if fields:
                    out.extend(["| # | field | type | description |", "| --- | --- | --- | --- |"])
                    for _, typ, name, number, note, oneof in fields:
                        note = (f"(oneof `{oneof}`) " if oneof else "") + note
                        out.append(f"| {number} | `{name}` | `{cell(typ)}` | {cell(note)} |")
                    out.append("")
                if values:
                    out.extend(["| value | number | description |", "| --- | --- | --- |"])
                    out.extend([f"| `{v[1]}` | {v[2]} | {cell(v[3])} |" for v in values])
                    out.append("")
                walk(child, depth + 1)

        walk(root, 3)
    return "\n".join(out).rstrip("\n") + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--source", required=True)
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true")
    mode.add_argument("--write", action="store_true")
    args = parser.parse_args()
    page = os.path.join(args.source, PAGE)
    text = render(args.source)
    if args.write:
        with open(page, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"wrote {PAGE}")
        return 0
    current = open(page, encoding="utf-8").read() if os.path.exists(page) else ""
    if current != text:
        print(f"{PAGE} differs from the protos' comments: regenerate it with "
              "tests/docs/proto_reference.py --source . --write", file=sys.stderr)
        return 1
    print(f"{PAGE} is up to date")
    return 0


if __name__ == "__main__":
    sys.exit(main())
