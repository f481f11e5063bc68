#!/usr/bin/env python3
"""Checks that README.md and docs/ agree with the source, and that their links resolve.

- Every block introduced by `<!-- help: PROGRAM [COMMAND] -->` (a fenced text block on the next
  lines) is exactly what `PROGRAM [COMMAND] --help` prints; every block introduced by
  `<!-- output: PROGRAM ARGS -->` is exactly what that command prints. PROGRAM is one of the
  built programs (radiosity, radiosity-server, ...), run from --bin.
- Every relative link ([text](path) or [text](path#anchor)) names a file or directory of the
  repository, and an anchor names a heading of the Markdown file it points into (GitHub's rule:
  lower case, punctuation dropped, spaces to hyphens, -1, -2 ... for repeats).

Usage: check_docs.py --bin DIR --source DIR [--fix] [PAGE.md ...]
With no pages: README.md and every page under docs/. --fix rewrites the generated blocks from
the programs' output instead of failing on them (links are still checked). Exit code 1 lists
every disagreement.
"""

import argparse
import glob
import os
import re
import subprocess
import sys

from fences import code_lines, fenced_blocks

MARKER = re.compile(r"^<!--\s*(help|output):\s*(.+?)\s*-->\s*$")
LINK = re.compile(r"(?<!!)\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)|"
                  r"!\[[^\]]*\]\(([^)\s]+)\)")
INLINE_CODE = re.compile(r"`[^`]*`")


def run(bin_dir, words):
    """stdout of the built program words[0] with arguments words[1:] (argv[0] its bare name)."""
    program = os.path.join(bin_dir, words[0])
    if not os.path.isfile(program):
        return None, f"{words[0]} is not a built program in {bin_dir}"
    proc = subprocess.run([words[0]] + words[1:], executable=program, capture_output=True,
                          text=True, timeout=60)
    if proc.returncode != 0:
        return None, f"`{' '.join(words)}` exited {proc.returncode}: {proc.stderr.strip()}"
    return proc.stdout, None


def normalise(text):
    return "\n".join(line.rstrip() for line in text.strip("\n").split("\n"))


def generated_blocks(path, lines, bin_dir, fix):
    """Problems with the generated blocks of one page; with `fix`, the page's lines corrected."""
    problems = []
    opening = {b.start: b for b in fenced_blocks(lines)}
    i = 0
    while i < len(lines):
        m = MARKER.match(lines[i])
        if not m:
            i += 1
            continue
        kind, command = m.group(1), m.group(2).split()
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        if j not in opening:
            problems.append(f"{path}:{i + 1}: <!-- {kind}: ... --> is not followed by a fenced "
                            "block")
            i += 1
            continue
        k = opening[j].end
        words = command + (["--help"] if kind == "help" else [])
        expected, error = run(bin_dir, words)
        if error:
            problems.append(f"{path}:{i + 1}: {error}")
        elif normalise("\n".join(lines[j + 1:k])) != normalise(expected):
            if fix:
                lines[j + 1:k] = normalise(expected).split("\n")
                opening = {b.start: b for b in fenced_blocks(lines)}
                k = opening[j].end
            else:
                problems.append(f"{path}:{j + 1}: the block differs from `{' '.join(words)}`; "
                                "regenerate it with tests/docs/check_docs.py --fix, or paste:\n"
                                + expected)
        i = k + 1
    return problems


def slug(heading, seen):
    text = re.sub(r"<[^>]+>", "", heading).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text, flags=re.UNICODE).replace(" ", "-")
    n = seen.get(text, 0)
    seen[text] = n + 1
    return text if n == 0 else f"{text}-{n}"


def anchors(path, cache={}):
    if path not in cache:
        seen, found = {}, set()
        with open(path, encoding="utf-8") as f:
            lines = f.read().split("\n")
        code = code_lines(lines)
        for n, line in enumerate(lines):
            if n not in code and re.match(r"^#{1,6}\s", line):
                found.add(slug(line.lstrip("#").strip(), seen))
            for a in re.findall(r"<a\s+(?:name|id)=\"([^\"]+)\"", line):
                found.add(a)
        cache[path] = found
    return cache[path]


def links(path, lines, source):
    problems = []
    code = code_lines(lines)
    for n, line in enumerate(lines, 1):
        if n - 1 in code:
            continue
        for m in LINK.finditer(INLINE_CODE.sub("", line)):
            target = m.group(1) or m.group(2)
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                continue  # http:, https:, mailto:
            file_part, _, anchor = target.partition("#")
            resolved = os.path.normpath(os.path.join(os.path.dirname(path), file_part)) \
                if file_part else path
            if not os.path.exists(resolved):
                problems.append(f"{os.path.relpath(path, source)}:{n}: link {target}: "
                                f"{os.path.relpath(resolved, source)} does not exist")
            elif anchor and resolved.endswith(".md") and anchor not in anchors(resolved):
                problems.append(f"{os.path.relpath(path, source)}:{n}: link {target}: no heading "
                                f"#{anchor} in {os.path.relpath(resolved, source)}")
    return problems


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bin", required=True)
    parser.add_argument("--source", required=True)
    parser.add_argument("--fix", action="store_true")
    parser.add_argument("pages", nargs="*")
    args = parser.parse_args()
    source = os.path.abspath(args.source)
    pages = [os.path.abspath(p) for p in args.pages] or (
        [os.path.join(source, "README.md")] +
        sorted(glob.glob(os.path.join(source, "docs", "**", "*.md"), recursive=True)))
    problems = []
    for page in pages:
        lines = open(page, encoding="utf-8").read().split("\n")
        rel = os.path.relpath(page, source)
        before = list(lines)
        problems += generated_blocks(rel, lines, args.bin, args.fix)
        if args.fix and lines != before:
            with open(page, "w", encoding="utf-8") as f:
                f.write("\n".join(lines))
            print(f"regenerated blocks of {rel}")
        problems += links(page, lines, source)
    for p in problems:
        print(p, file=sys.stderr)
    print(f"{len(pages)} pages, {len(problems)} problems")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
