"""The project's import picture: the module graph inside each crate, and the crates' layers.

    python3 tools/imports.py           # exit 1 naming a circle or an upward dependency, else 0
    python3 tools/imports.py --print   # also print every crate's module graph

A module is a file (`mod.rs`, `lib.rs` and `main.rs` stand for their folder's module), found
by following the `mod NAME;` declarations from each crate root (`src/lib.rs`, `src/main.rs`,
`[lib]`/`[[bin]]` paths); an inline `mod NAME { ... }` (a `#[cfg(test)] mod tests`) is a module
of its own, below the file that holds it, as Rust has it. An edge A -> B is a path in A's code
that names B: `use crate::b::X`, `crate::b::f()`, `super::b`, `self::b`, or a child module's
name; comments and strings do not count, nor do `mod` declarations. A path through a module's
`pub use` lands on the module the item comes from (`crate::PointCloud` -> `cloud`), so a crate
root's re-exports make no circle of their own. Any circle in any crate fails the check.

Layers: every crate names its layer in LAYERS below; a crate may depend (dependencies,
dev-dependencies and build-dependencies alike) only on rgm crates of a lower layer. A crate
missing from LAYERS fails the check too, so a new crate is placed on purpose.

.ci/run runs it after scripts/tree-size.sh. Plain Python 3.8+, no packages.
"""

import os
import re
import sys

sys.setrecursionlimit(10000)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# The layering, bottom first: a crate may use only crates of a lower number (docs/architecture.md).
LAYERS = {
    "rgm-geom": 0,  # geometry: clouds, transforms, kNN, Kabsch, normals, FPFH, metrics
    "rgm-nn": 0,  # tensors, ops, optimisers, weights
    "rgm-registration": 1,  # the classical methods, traits, wrappers, composites, checks
    "rgm-match": 1,  # affinity, Sinkhorn, assignment (rgm-nn; rgm-geom's lockstep)
    "rgm-data": 1,  # point-cloud files, ModelNet40, the pair protocol
    "rgm-model": 2,  # the network and the composition of the named methods
    "rgm-viz": 2,  # pictures and pages of a registration
    "rgm-tests": 3,  # cross-crate tests and the helpers rgm-cli's tests share
    "rgm-cli": 4,  # the `rgm` command
    "xtask": 5,  # benchmarks and reproductions
    "rgm-benches": 5,  # criterion benches of every crate
    "rgm-python": 5,  # the Python package (python/, its own workspace)
}

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


def strip(text):
    """The code with comments, strings and char literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif re.match(r'b?r#*"', text[i:i + 20]) and (i == 0 or not re.match(r"\w", text[i - 1])):
            m = re.match(r'b?r(#*)"', text[i:])
            end = text.find('"' + m.group(1), i + m.end())
            j = n if end < 0 else end + 1 + len(m.group(1))
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(re.sub(r"[^\n]", " ", text[i:j + 1]))
            i = j + 1
        elif c == "'":
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\x[0-9a-fA-F]{2}|\\.|[^\\'])'", text[i:])
            if m:
                out.append(" " * m.end())
                i += m.end()
            else:  # a lifetime
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def use_paths(tree):
    """The paths of one `use` tree: `a::{b, c::{d as e, *}}` -> [(['a','b'], 'b'), ...]."""
    tokens = re.findall(IDENT + r"|::|[{},*]", tree)
    pos = 0

    def parse(prefix):
        nonlocal pos
        paths = []
        segs = list(prefix)
        while pos < len(tokens):
            t = tokens[pos]
            if t == "{":
                pos += 1
                while tokens[pos] != "}":
                    paths += parse(segs)
                    if tokens[pos] == ",":
                        pos += 1
                pos += 1
                return paths
            if t in (",", "}"):
                break
            if t == "::":
                pos += 1
                continue
            if t == "as":
                pos += 2
                return paths + [(segs, tokens[pos - 1])]
            segs = segs + [t]
            pos += 1
        if segs != list(prefix):
            last = segs[-1]
            if last == "self":
                segs = segs[:-1]
                last = segs[-1] if segs else "self"
            paths.append((segs, last))
        return paths

    return parse([])


class Module:
    def __init__(self, name, file, parent, code, child_dir):
        self.name, self.file, self.parent = name, file, parent
        self.code = code  # this module's own code: inline child modules blanked
        self.child_dir = child_dir  # where `mod x;` finds x.rs or x/mod.rs
        self.children = {}
        self.reexports = {}  # name -> (module, path) of a `pub use`
        self.edges = {}  # target name -> line of the first path that names it


def split_inline(code):
    """(code without inline modules, [(name, body)]) for the `mod NAME { ... }` blocks."""
    found = []
    outer = list(code)
    for m in re.finditer(r"\bmod\s+(" + IDENT + r")\s*\{", code):
        if any(s <= m.start() < e for _, s, e in found):
            continue
        depth, j = 1, m.end()
        while j < len(code) and depth:
            depth += {"{": 1, "}": -1}.get(code[j], 0)
            j += 1
        found.append((m.group(1), m.end(), j - 1))
    for _, s, e in found:
        for k in range(s, e):
            if outer[k] != "\n":
                outer[k] = " "
    # An inline module keeps its lines: blank what comes before it so line numbers hold.
    inline = []
    for name, s, e in found:
        body = re.sub(r"[^\n]", " ", code[:s]) + code[s:e]
        inline.append((name, body))
    return "".join(outer), inline


def load_crate(roots):
    """Every module reached from the roots: {full name: Module}."""
    modules = {}

    def add(name, file, parent, code, child_dir):
        own, inline = split_inline(code)
        mod = Module(name, file, parent, own, child_dir)
        modules[name] = mod
        for child in re.findall(r"\bmod\s+(" + IDENT + r")\s*;", own):
            for cand in (os.path.join(child_dir, child + ".rs"),
                         os.path.join(child_dir, child, "mod.rs")):
                if os.path.exists(cand):
                    full = name + "::" + child
                    mod.children[child] = full
                    sub_dir = (os.path.dirname(cand) if cand.endswith("mod.rs")
                               else os.path.join(child_dir, child))
                    add(full, cand, name, strip(open(cand, encoding="utf-8").read()), sub_dir)
                    break
        for child, body in inline:
            full = name + "::" + child
            mod.children[child] = full
            add(full, file, name, body, os.path.join(child_dir, child))
        return mod

    for root_name, path in roots:
        add(root_name, path, None, strip(open(path, encoding="utf-8").read()),
            os.path.dirname(path))
    return modules


def resolve(modules, cur, segs, children=False, seen=()):
    """The module a path from module `cur` lands on, or None for another crate's path (or,
    unless `children`, for a path that starts at one of `cur`'s own child modules)."""
    m = modules[cur]
    first = segs[0]
    rest = segs[1:]
    if first == "crate":
        while m.parent is not None:
            m = modules[m.parent]
    elif first == "super":
        m = modules[m.parent]
        while rest and rest[0] == "super":
            m, rest = modules[m.parent], rest[1:]
    elif first == "self":
        pass
    elif first in m.children and children:
        rest = segs
    else:
        return None
    for seg in rest:
        if seg in m.children:
            m = modules[m.children[seg]]
        elif seg in m.reexports and (m.name, seg) not in seen:
            origin, path = m.reexports[seg]
            target = resolve(modules, origin, path, True, seen + ((m.name, seg),))
            if target is not None:
                m = modules[target]
            break
        else:
            break
    return m.name


def line_of(code, index):
    return code.count("\n", 0, index) + 1


def crate_graph(modules):
    # First the re-exports (a `pub use` names where its items come from), then the edges.
    uses = {}
    for mod in modules.values():
        uses[mod.name] = []
        for m in re.finditer(r"(\bpub\s*(\([^)]*\))?\s*)?\buse\s+([^;]+);", mod.code):
            for segs, last in use_paths(m.group(3)):
                uses[mod.name].append((segs, m.start()))
                if m.group(1) and last != "*" and segs:
                    mod.reexports[last] = (mod.name, segs)
    for mod in modules.values():
        code = mod.code
        spans = []
        for segs, at in uses[mod.name]:
            spans.append((segs, at))
        use_ranges = [(m.start(), m.end()) for m in re.finditer(r"\buse\s+[^;]+;", code)]
        for m in re.finditer(r"(?<![\w:])(" + IDENT + r")((?:\s*::\s*" + IDENT + r")+)", code):
            if any(s <= m.start() < e for s, e in use_ranges):
                continue
            segs = [m.group(1)] + re.findall(IDENT, m.group(2))
            spans.append((segs, m.start()))
        for segs, at in spans:
            if not segs:
                continue
            target = resolve(modules, mod.name, segs)
            if target is not None and target != mod.name:
                mod.edges.setdefault(target, line_of(code, at))
    return {name: mod.edges for name, mod in modules.items()}


def components(graph):
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, {})):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                out.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def cycle_in(graph, part):
    """One circle through the first module of a component, as a list (first repeated last)."""
    start, inside = part[0], set(part)
    paths = {start: [start]}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph.get(v, {})):
            if w == start:
                return paths[v] + [start]
            if w in inside and w not in paths:
                paths[w] = paths[v] + [w]
                queue.append(w)
    return part + [start]


def toml_sections(path):
    """{section: [lines]} of a Cargo.toml, plainly read (no TOML package needed)."""
    sections, current = {}, ""
    for line in open(path, encoding="utf-8"):
        line = line.split("#", 1)[0].rstrip()
        m = re.match(r"^\s*\[\[?([^\]]+)\]\]?\s*$", line)
        if m:
            current = m.group(1).strip()
            sections.setdefault(current, [])
            if line.strip().startswith("[["):
                sections[current].append("--")
        elif line.strip():
            sections.setdefault(current, []).append(line.strip())
    return sections


def packages():
    """(name, folder, Cargo.toml sections) of every package of the project."""
    found = []
    for folder in sorted(os.listdir(os.path.join(ROOT, "crates"))):
        found.append(os.path.join("crates", folder))
    found += ["benches", "tests", "xtask", "python"]
    out = []
    for folder in found:
        toml = os.path.join(ROOT, folder, "Cargo.toml")
        if not os.path.exists(toml):
            continue
        sections = toml_sections(toml)
        name = next(re.match(r'name\s*=\s*"([^"]+)"', l).group(1)
                    for l in sections.get("package", []) if l.startswith("name"))
        out.append((name, folder, sections))
    return out


def roots_of(folder, sections):
    roots = []
    lib = [l for l in sections.get("lib", []) if l.startswith("path")]
    lib_path = re.search(r'"([^"]+)"', lib[0]).group(1) if lib else "src/lib.rs"
    if os.path.exists(os.path.join(ROOT, folder, lib_path)):
        roots.append(("crate", os.path.join(ROOT, folder, lib_path)))
    bins = [re.search(r'"([^"]+)"', l).group(1) for l in sections.get("bin", [])
            if l.startswith("path")]
    if not bins and os.path.exists(os.path.join(ROOT, folder, "src/main.rs")):
        bins = ["src/main.rs"]
    for b in bins:
        roots.append(("bin " + os.path.splitext(os.path.basename(b))[0],
                      os.path.join(ROOT, folder, b)))
    return roots


def main():
    show = "--print" in sys.argv[1:]
    failures = []
    for name, folder, sections in packages():
        if name not in LAYERS:
            failures.append(f"{name} ({folder}) has no layer in tools/imports.py's LAYERS")
            continue
        deps = []
        for section, lines in sections.items():
            if section.split(".")[-1].endswith("dependencies"):
                for l in lines:
                    dep = re.match(r"([A-Za-z0-9_-]+)(\.workspace)?\s*=", l)
                    if dep and dep.group(1) in LAYERS:
                        deps.append((dep.group(1), section))
        if show:
            names = sorted({d for d, _ in deps})
            print(f"{name} (layer {LAYERS[name]}) uses: {', '.join(names) or 'no rgm crate'}")
        for dep, section in deps:
            if LAYERS[dep] >= LAYERS[name]:
                failures.append(f"{name} (layer {LAYERS[name]}) [{section}] depends on {dep} "
                                f"(layer {LAYERS[dep]}), not below it")
        for root_name, path in roots_of(folder, sections):
            modules = load_crate([(root_name, path)])
            graph = crate_graph(modules)
            label = name if root_name == "crate" else f"{name} ({root_name})"
            if show:
                for mod in sorted(graph):
                    rel = os.path.relpath(modules[mod].file, ROOT)
                    targets = ", ".join(sorted(graph[mod]))
                    print(f"  {mod} [{rel}] -> {targets or '-'}")
            for part in components(graph):
                cycle = cycle_in(graph, part)
                steps = " -> ".join(
                    f"{a} ({os.path.relpath(modules[a].file, ROOT)}:{graph[a][b]})"
                    for a, b in zip(cycle, cycle[1:]))
                failures.append(f"{label}: import circle {steps} -> {cycle[-1]}")
    for f in failures:
        print("imports.py: " + f, file=sys.stderr)
    if failures:
        sys.exit(1)
    print("imports.py: no import circle in any crate, no dependency pointing up")


if __name__ == "__main__":
    main()
