"""The fenced code blocks of a Markdown page, for run_docs.py and check_docs.py.

A block opens on a line of three or more backticks (or tildes), optionally indented and followed
by its info string, and closes on the next line that starts with the same fence, so a block
fenced by four backticks may hold three-backtick lines. An unclosed block runs to the end.
"""

import re

FENCE = re.compile(r"^\s*(`{3,}|~{3,})\s*(.*)$")


class Fenced:
    def __init__(self, start, end, fence, info):
        self.start = start  # index of the opening fence's line
        self.end = end      # index of the closing fence's line (len(lines) when unclosed)
        self.fence = fence
        self.info = info    # the info string's words: ["sh", "runnable"]

    def body(self, lines):
        return lines[self.start + 1:self.end]


def fenced_blocks(lines):
    """The fenced blocks of `lines` (a page split at newlines), in order."""
    blocks = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        end = i + 1
        while end < len(lines) and not lines[end].strip().startswith(m.group(1)):
            end += 1
        blocks.append(Fenced(i, end, m.group(1), m.group(2).split()))
        i = end + 1
    return blocks


def code_lines(lines):
    """Indices of the lines that are fences or inside fenced blocks."""
    inside = set()
    for b in fenced_blocks(lines):
        inside.update(range(b.start, min(b.end, len(lines) - 1) + 1))
    return inside
