#!/usr/bin/env python3
"""Lists C++ functions that take more than a limit of parameters (default 6).

    tools/function_params.py [--limit N] [--all] PATH...

Counts the parameters of every function definition and declaration (free functions, members,
constructors, operators), every lambda and every function type written as a pointer
(`using K = void (*)(...)`) or inside std::function<...>. A small lexer, not a compiler (it shares
function_lengths.py's): comments, strings and preprocessor lines are skipped; at namespace and class
scope a statement whose first parenthesis follows a name, with no `=` before it, is a function; a
comma counts only outside nested (), <>, [] and {}. Exit status 1 when some function takes more than
the limit (the rule of docs/design.md: longer lists travel in named structs).

EXCLUDED names, per file, the signatures that are not checked (each with its reason)."""
import argparse
import importlib.util
import pathlib
import re
import sys

_spec = importlib.util.spec_from_file_location("function_lengths", pathlib.Path(__file__).with_name("function_lengths.py"))
_lengths = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_lengths)
strip = _lengths.strip

# Signatures that are not checked, per file (none now).
EXCLUDED = {}

NOT_NAMES = {"if", "for", "while", "switch", "return", "sizeof", "alignof", "alignas", "decltype", "noexcept",
             "static_assert", "requires", "__attribute__", "__declspec", "catch", "throw", "new", "delete"}


def matching(text, i, open_c, close_c):
    """Index just past the bracket that closes text[i] (== open_c)."""
    depth = 0
    for j in range(i, len(text)):
        if text[j] == open_c:
            depth += 1
        elif text[j] == close_c:
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


def count_params(inside):
    """Parameters in the text between a parameter list's parentheses."""
    body = inside.strip()
    if not body or body == "void":
        return 0
    depth, angle, count = 0, 0, 1
    for k, c in enumerate(body):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "<" and depth == 0 and re.search(r"[\w:>]\s*$", body[:k]) and not body[:k].rstrip().endswith("operator"):
            angle += 1
        elif c == ">" and depth == 0 and angle > 0:
            angle -= 1
        elif c == "," and depth == 0 and angle == 0:
            count += 1
    return count


def skip_angles(text, i):
    """From text[i] == '<', the index past its closing '>' (nested <> and () counted)."""
    depth = 0
    for j in range(i, len(text)):
        c = text[j]
        if c in "<(":
            depth += 1
        elif c in ">)":
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


def named_function(header):
    """(name, parameters) of a statement at namespace or class scope that declares or defines a
    function, else None."""
    h = header
    # Leading template heads and attributes.
    while True:
        h = h.lstrip()
        m = re.match(r"template\s*<", h)
        if m:
            h = h[skip_angles(h, m.end() - 1):]
            continue
        m = re.match(r"(__attribute__\s*\(|\[\[)", h)
        if m:
            h = h[matching(h, m.start() if h[0] == "[" else m.end() - 1, h[0] if h[0] == "[" else "(",
                           "]" if h[0] == "[" else ")"):]
            if h.startswith("]"):
                h = h[1:]
            continue
        break
    if re.match(r"(namespace|using|typedef|static_assert|friend\s+(class|struct))\b", h):
        return None
    i, angle = 0, 0
    while i < len(h):
        c = h[i]
        if c == "<" and re.search(r"\w\s*$", h[:i]) and not re.search(r"operator\s*$", h[:i]):
            i = skip_angles(h, i)
            continue
        if c == "=" and not re.search(r"operator\s*[=!<>+\-*/%&|^]*$", h[: i + 1]):
            return None  # an initializer: what follows is a call
        if c == "(":
            before = h[:i].rstrip()
            m = re.search(r"(operator\s*(\(\)|\[\]|[^\w\s(]+)|~?[A-Za-z_]\w*)$", before)
            if not m or m.group(1) in NOT_NAMES:
                if m and m.group(1) == "__attribute__":
                    i = matching(h, i, "(", ")")
                    continue
                return None
            end = matching(h, i, "(", ")")
            return re.sub(r"\s+", "", m.group(1)), count_params(h[i + 1 : end - 1])
        if c in "{;":
            return None
        i += 1
    return None


def signatures(path):
    """(line, name, parameters) of every function, lambda and function type in the file."""
    text = strip(path.read_text())
    line_of = lambda i: text.count("\n", 0, i) + 1
    found = []
    # Named functions: statements at namespace or class scope.
    stack, start = [], 0
    for i, c in enumerate(text):
        if c in "{;}":
            outer = stack[-1] if stack else "ns"
            if outer in ("ns", "class") and c != "}":
                header = text[start:i]
                hit = named_function(header)
                if hit:
                    found.append((line_of(start + len(header) - len(header.lstrip())), hit[0], hit[1]))
            if c == "{":
                header = text[start:i]
                if outer not in ("ns", "class"):
                    kind = "other"
                elif re.search(r"\bnamespace\b", header) or re.search(r"\bextern\s*$", header):
                    kind = "ns"
                elif re.search(r"\b(class|struct|union|enum)\b", header) and "(" not in header.split(":")[0]:
                    kind = "class"
                else:
                    kind = "other"
                stack.append(kind)
            elif c == "}" and stack:
                stack.pop()
            start = i + 1
    # Lambdas: a capture list where an expression starts (not a subscript, not an attribute).
    for m in re.finditer(r"\[", text):
        i = m.start()
        prev = text[:i].rstrip()[-1:] if text[:i].strip() else ""
        if (prev and (prev.isalnum() or prev in "_)]")) or text[i + 1 : i + 2] == "[" or text[i - 1 : i] == "[":
            continue
        j = matching(text, i, "[", "]")
        rest = text[j:]
        k = len(rest) - len(rest.lstrip())
        if rest[k : k + 1] == "<":
            k = skip_angles(rest, k)
            k += len(rest[k:]) - len(rest[k:].lstrip())
        if rest[k : k + 1] != "(":
            continue
        end = matching(rest, k, "(", ")")
        found.append((line_of(i), "lambda", count_params(rest[k + 1 : end - 1])))
    # Function types: pointers (R (*name)(...), R (*)(...)) and std::function<R(...)>.
    for m in re.finditer(r"\(\s*\*\s*(\w*)\s*\)\s*\(|\bfunction\s*<[^<>(;{}]*\(", text):
        k = m.end() - 1
        end = matching(text, k, "(", ")")
        name = m.group(1) or ""
        if not name:
            u = re.search(r"using\s+(\w+)\s*=[^;]*$", text[: m.start()])
            name = u.group(1) if u else "function type"
        found.append((line_of(m.start()), name, count_params(text[k + 1 : end - 1])))
    return found


def excluded(path, name, root):
    try:
        rel = path.resolve().relative_to(root).as_posix()
    except ValueError:
        return False
    names = EXCLUDED.get(rel)
    return names == "*" or (names is not None and name in names)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=6)
    ap.add_argument("--all", action="store_true", help="list every signature, most parameters first")
    ap.add_argument("paths", nargs="+")
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    found = []
    for p in args.paths:
        top = pathlib.Path(p)
        files = [top] if top.is_file() else sorted(list(top.rglob("*.cpp")) + list(top.rglob("*.h")))
        for f in files:
            for line, name, count in signatures(f):
                if not excluded(f, name, root):
                    found.append((count, f"{f}:{line}", name))
    found.sort(key=lambda x: (-x[0], x[1]))
    many = [x for x in found if x[0] > args.limit]
    for count, where, name in (found if args.all else many):
        print(f"{count:3d}  {where}  {name}")
    return 1 if many else 0


if __name__ == "__main__":
    sys.exit(main())
