#!/usr/bin/env python3
"""Checks that the scene-file reference names every key and every choice the JSON parser accepts.

    tools/check_scene_docs.py [--list] SOURCE_ROOT

Reads the parser's sources (lib/src/scene/parse_json.cpp, parse_capture.cpp, parse_sensor.cpp):
the keys are the names passed to `check_keys({...})` (the parser refuses any other key) and to
`child("...")` / `find("...")`; the choices are the names of types and modes that the parser compares
a string with (`name == "mirror"`, `shape == "box"`) or passes to `parse_choice` (`{"flat", ...}`).
Each must appear in docs/scene.md as inline code: `key`, `"key"`, or the last part of a dotted path
such as `links.tolerance`. Exit status 1, listing what is missing, when one does not (the rule that
the reference is complete; CTest: Architecture.SceneKeysDocumented); 0 otherwise. --list prints
every name found with where it comes from."""
import argparse
import pathlib
import re
import sys

PARSERS = ["parse_json.cpp", "parse_capture.cpp", "parse_sensor.cpp"]

# A call with a list of names: check_keys({"a", "b"}) (spread over lines).
CHECK_KEYS = re.compile(r"check_keys\(\s*\{([^}]*)\}\s*\)", re.S)
# One member read: child("a") or find("a").
MEMBER = re.compile(r"\b(?:child|find)\(\s*\"([A-Za-z_0-9]+)\"\s*\)")
# A string compared with a type's or mode's name: name == "laser", shape != "delta".
COMPARED = re.compile(r"\b(?:name|shape)\s*[!=]=\s*\"([A-Za-z_0-9]+)\"")
# parse_choice's table: {{"nearest", DelayMode::Nearest}, {"linear", DelayMode::Linear}}.
CHOICE = re.compile(r"\{\s*\"([A-Za-z_0-9]+)\"\s*,\s*[A-Z]\w*::\w+\s*\}")
STRING = re.compile(r"\"([^\"\\]*)\"")
CODE_SPAN = re.compile(r"`([^`\n]+)`")


def strip_comments(text):
    """Drops // comments (the parsers quote key names in them too) but keeps string literals."""
    out = []
    for line in text.splitlines():
        in_string, i = False, 0
        while i < len(line):
            c = line[i]
            if c == "\\" and in_string:
                i += 2
                continue
            if c == '"':
                in_string = not in_string
            elif not in_string and line.startswith("//", i):
                line = line[:i]
                break
            i += 1
        out.append(line)
    return "\n".join(out)


def parser_names(root):
    """{name: [where found]} for every key and choice of the JSON scene and sensor parsers."""
    names = {}
    for file in PARSERS:
        path = root / "lib" / "src" / "scene" / file
        text = strip_comments(path.read_text(encoding="utf-8"))
        found = []
        for block in CHECK_KEYS.findall(text):
            found += [(n, "check_keys") for n in STRING.findall(block)]
        found += [(n, "member") for n in MEMBER.findall(text)]
        found += [(n, "choice") for n in COMPARED.findall(text)]
        found += [(n, "choice") for n in CHOICE.findall(text)]
        for name, kind in found:
            names.setdefault(name, []).append(f"{file} ({kind})")
    return names


def documented(doc_text):
    """Every name the page shows as inline code: the span itself, unquoted, and each dotted part."""
    shown = set()
    for span in CODE_SPAN.findall(doc_text):
        span = span.strip()
        shown.add(span)
        unquoted = span.strip('"')
        shown.add(unquoted)
        shown.update(part for part in unquoted.split(".") if part)
    return shown


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=pathlib.Path, help="the source tree (holds lib/ and docs/)")
    parser.add_argument("--list", action="store_true", help="print every name found and where")
    args = parser.parse_args()
    names = parser_names(args.root)
    if len(names) < 20:  # the parsers changed shape: this check would pass without checking anything
        print(f"check_scene_docs: found only {len(names)} names in {', '.join(PARSERS)}; update the patterns",
              file=sys.stderr)
        return 1
    if args.list:
        for name in sorted(names):
            print(f"{name}: {', '.join(sorted(set(names[name])))}")
    doc = args.root / "docs" / "scene.md"
    shown = documented(doc.read_text(encoding="utf-8"))
    missing = sorted(n for n in names if n not in shown)
    if missing:
        print(f"{doc}: {len(missing)} of the {len(names)} keys and choices that the scene parser accepts are not "
              "documented (as `name` in inline code):", file=sys.stderr)
        for name in missing:
            print(f"  {name}  (from {', '.join(sorted(set(names[name])))})", file=sys.stderr)
        return 1
    print(f"{doc}: all {len(names)} keys and choices of the scene parser are documented")
    return 0


if __name__ == "__main__":
    sys.exit(main())
