#!/usr/bin/env python3
"""Lists C++ functions longer than a limit (default 80 lines, signature to closing brace).

    tools/function_lengths.py [--limit N] [--all] PATH...

A small lexer, not a compiler: comments, strings and preprocessor lines are skipped, and a brace
block at namespace or class scope whose header holds a parameter list is a function. Exit status 1
when some function is longer than the limit (the architecture rule of docs/design.md)."""
import argparse
import pathlib
import re
import sys


def strip(text):
    """Blanks comments, string and char literals and preprocessor lines, keeping newlines."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif c == 'R' and text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = text.find(")" + m.group(1) + '"', i) + len(m.group(1)) + 2
            out.append("\n" * text.count("\n", i, end))
            i = end
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(" ")
            i = j + 1
        elif c == "#" and (i == 0 or text[i - 1] == "\n" or text[:i].rstrip(" \t").endswith("\n")):
            j = i
            while True:
                k = text.find("\n", j)
                if k < 0:
                    k = n
                    break
                if text[k - 1] != "\\":
                    break
                j = k + 1
            i = k
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    text = strip(path.read_text())
    stack = []          # kinds of open blocks: 'ns', 'class', 'fn', 'other'
    header_start = 0    # offset where the current statement's header begins
    results = []
    for i, c in enumerate(text):
        if c == "{":
            header = text[header_start:i]
            outer = stack[-1][0] if stack else "ns"
            words = header.split()
            if outer in ("ns", "class"):
                if re.search(r"\b(namespace)\b", header):
                    kind = "ns"
                elif re.search(r"\b(class|struct|union|enum)\b", header) and "(" not in header.split("{")[0].split(":")[0]:
                    kind = "class"
                elif "(" in header and not header.rstrip().endswith("="):
                    kind = "fn"
                else:
                    kind = "other"
            else:
                kind = "other"
            start_line = text.count("\n", 0, header_start + len(header) - len(header.lstrip())) + 1
            stack.append((kind, start_line, header.strip()))
            header_start = i + 1
        elif c == "}":
            if stack:
                kind, start_line, header = stack.pop()
                if kind == "fn":
                    end_line = text.count("\n", 0, i) + 1
                    name = re.sub(r"\s+", " ", header.split("(")[0]).split(" ")[-1]
                    results.append((end_line - start_line + 1, name, start_line))
            header_start = i + 1
        elif c == ";":
            header_start = i + 1
    return results


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=80)
    ap.add_argument("--all", action="store_true", help="list every function, longest first")
    ap.add_argument("paths", nargs="+")
    args = ap.parse_args()
    found = []
    for p in args.paths:
        root = pathlib.Path(p)
        files = [root] if root.is_file() else sorted(list(root.rglob("*.cpp")) + list(root.rglob("*.h")))
        for f in files:
            for length, name, line in functions(f):
                found.append((length, f"{f}:{line}", name))
    found.sort(reverse=True)
    long = [x for x in found if x[0] > args.limit]
    for length, where, name in (found if args.all else long):
        print(f"{length:5d}  {where}  {name}")
    return 1 if long else 0


if __name__ == "__main__":
    sys.exit(main())
