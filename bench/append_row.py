#!/usr/bin/env python3
"""Append one row to a markdown table in BENCHMARKS.md, creating the section if needed.

Usage: append_row.py FILE "SECTION HEADING" '["col", ...]' '["cell", ...]'

The row goes after the last table line of the section whose heading line is exactly
"## SECTION HEADING". The file is rewritten through a temporary file and a rename, so a crash
never leaves it half-written. Other sections are left byte-for-byte alone.
"""
import json
import os
import sys


def cells(line):
    return "| " + " | ".join(c.replace("|", "\\|") for c in line) + " |"


def main():
    if len(sys.argv) != 5:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    path, section, header, row = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
    if len(header) != len(row):
        sys.exit(f"append_row.py: {len(header)} columns but {len(row)} cells")
    text = open(path).read() if os.path.exists(path) else "# Benchmarks\n"
    lines = text.splitlines()
    heading = f"## {section}"
    if heading not in lines:
        if lines and lines[-1].strip():
            lines.append("")
        lines += [heading, "", cells(header), cells(["---"] * len(header))]
        at = len(lines)
    else:
        start = lines.index(heading) + 1
        end = next((i for i in range(start, len(lines)) if lines[i].startswith("## ")), len(lines))
        table = [i for i in range(start, end) if lines[i].lstrip().startswith("|")]
        if not table:
            lines[end:end] = ["", cells(header), cells(["---"] * len(header))]
            at = end + 3
        else:
            at = table[-1] + 1
    lines.insert(at, cells(row))
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
