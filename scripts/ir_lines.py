#!/usr/bin/env python3
"""Where a compile of cloudgi spends its code: LLVM IR lines per module, as cargo-llvm-lines counts.

Usage: scripts/ir_lines.py FILE.ll [DEPTH] [ROWS]

FILE.ll: unoptimised IR with v0 symbol names, e.g. of the library:
    cargo rustc --release --lib -- --emit=llvm-ir -C no-prepopulate-passes -C symbol-mangling-version=v0
(docs/performance.md, "Build and test time", says how to get the test harness's).

Each function is charged to the first cloudgi path in its symbol: the function itself, or, for a
dependency's generic (rayon's plumbing, iterator adapters), the cloudgi closure or type it was
instantiated for. Paths through a `tests` module are marked T. Prints the total, the share of
rayon's code and the largest modules cut at DEPTH path segments (default 3).
"""
import collections
import re
import sys


def cloudgi_path(symbol):
    """The identifiers after the first `cloudgi` crate root in a v0 symbol that names an item, or
    None (a symbol ends with the crate that instantiated it: that alone is no cloudgi item)."""
    start = 0
    while True:
        i = symbol.find("7cloudgi", start)
        if i < 0:
            return None
        j, parts = i + len("7cloudgi"), []
        while j < len(symbol):
            disambiguator = re.match(r"s[0-9a-zA-Z]*_", symbol[j:])
            if disambiguator:
                j += len(disambiguator.group())
            length = re.match(r"(\d+)_?", symbol[j:])
            if not length or int(length.group(1)) == 0:
                break
            j += len(length.group())
            parts.append(symbol[j : j + int(length.group(1))])
            j += int(length.group(1))
        if parts:
            return parts
        start = i + 1


def main():
    path = sys.argv[1]
    depth = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    rows = int(sys.argv[3]) if len(sys.argv) > 3 else 30
    lines, functions = collections.Counter(), collections.Counter()
    rayon = 0
    key, count, is_rayon = None, 0, False
    with open(path, errors="replace") as ir:
        for line in ir:
            if line.startswith("define "):
                m = re.search(r'@("?)([^"(]+)\1\(', line)
                symbol = m.group(2) if m else "?"
                parts = cloudgi_path(symbol)
                if parts is None:
                    key = "(no cloudgi item: dependencies and std)"
                else:
                    key = ("T " if "tests" in parts else "  ") + "::".join(["cloudgi"] + parts[:depth])
                head = symbol[: symbol.find("7cloudgi")] if parts is not None else symbol
                is_rayon = "5rayon" in head or "10rayon_core" in head
                count = 1
            elif key is not None:
                count += 1
                if line.startswith("}"):
                    lines[key] += count
                    functions[key] += 1
                    rayon += count if is_rayon else 0
                    key = None
    total = sum(lines.values())
    tests = sum(v for k, v in lines.items() if k.startswith("T "))
    print(f"{total} IR lines in {sum(functions.values())} functions; rayon's code {100 * rayon / total:.1f} %; "
          f"test modules {100 * tests / total:.1f} %")
    for k, v in lines.most_common(rows):
        print(f"{v:9d} {100 * v / total:5.1f} % {functions[k]:6d} fns  {k}")


if __name__ == "__main__":
    main()
