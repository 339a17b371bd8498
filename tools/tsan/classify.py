#!/usr/bin/env python3
"""Sorts ThreadSanitizer reports (log files given as arguments) into those about tprf's own code and
those raised inside uninstrumented libraries, and exits 1 if any is tprf's.

A report is tprf's when one of its two accesses (or a mutex report's stack) has a frame from tprf's
sources (lib/, app/, tests/) among its two innermost frames: the access itself or the call that made
it. Reports whose innermost frames are all in libomp's runtime, Embree, TBB or the C library's
allocator, called from them, are listed as the libraries' (docs/reliability.md, "ThreadSanitizer")."""
import re
import sys

OWN = re.compile(r"/(lib|app|tests)/[^ ]+\.(cpp|h):\d+")


def reports(text):
    return [b for b in text.split("==================") if "WARNING: ThreadSanitizer" in b]


def stacks(block):
    parts = re.split(r"\n  (?=(?:Write|Read|Previous|Atomic|Location|Mutex|Thread))", block)
    out = []
    for p in parts:
        head = p.strip().splitlines()[0] if p.strip() else ""
        if head.startswith(("Location", "Mutex", "Thread")):
            continue
        frames = [l for l in p.splitlines() if re.match(r"\s+#\d", l)]
        if frames:
            out.append(frames)
    return out


def main():
    own, libraries = [], 0
    for path in sys.argv[1:]:
        for block in reports(open(path, errors="replace").read()):
            kind = re.search(r"WARNING: ThreadSanitizer: ([^(]+)", block).group(1).strip()
            if any(OWN.search(f) for s in stacks(block) for f in s[:2]):
                own.append((path, kind, block))
            else:
                libraries += 1
    for path, kind, block in own:
        print(f"{path}: {kind} in tprf's code:\n{block}")
    print(f"ThreadSanitizer: {len(own)} report(s) in tprf's code, {libraries} inside uninstrumented libraries")
    return 1 if own else 0


if __name__ == "__main__":
    sys.exit(main())
