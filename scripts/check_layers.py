#!/usr/bin/env python3
"""Checks the layering of the source: every quoted #include in common/<layer>/, master/ and
worker/ runs downward in base <- image <- scene <- render <- wire <- master, worker (master
and worker never include each other), smoke/ (the simulator) includes only base, scene and
itself, and no circle joins modules (a module is a .c/.h
pair; an include from either file is an arrow). Prints one line per violation, naming the
file and line, and exits 1 if there is any. Run by `make test` (tests/layers/run.sh).
Usage: check_layers.py [--root DIR] [--graph]"""
import os
import re
import sys

LAYERS = ["base", "image", "scene", "render", "wire"]
RANK = {name: i for i, name in enumerate(LAYERS)}
RANK["master"] = RANK["worker"] = len(LAYERS)
# Programs outside the render stack: the layers each may include, besides itself.
SIDE = {"smoke": ("base", "scene")}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def layer_of(path):
    """The layer of a module path relative to the root: common/<layer>/x, master/x, worker/x."""
    parts = path.split("/")
    if parts[0] == "common" and len(parts) == 3 and parts[1] in RANK:
        return parts[1]
    if parts[0] in ("master", "worker") + tuple(SIDE) and len(parts) == 2:
        return parts[0]
    return None


def sources(root):
    out = []
    for top in ("common", "master", "worker") + tuple(SIDE):
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if f.endswith((".c", ".h")):
                    out.append(os.path.relpath(os.path.join(dirpath, f), root))
    return sorted(out)


def resolve(root, src, inc):
    """Where the compiler finds a quoted include: the file's own folder, then -Icommon, then -I."""
    for base in (os.path.dirname(src), "common", "."):
        cand = os.path.normpath(os.path.join(base, inc))
        if os.path.isfile(os.path.join(root, cand)):
            return cand
    return None


def circles(graph):
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    comps.append(sorted(comp))
    return comps


def cycle_path(graph, comp):
    """One concrete circle through the component, for the message: a -> b -> ... -> a."""
    members = set(comp)
    start = comp[0]
    prev, queue = {start: None}, [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph.get(v, ())):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return list(reversed(path)) + [start]
            if w in members and w not in prev:
                prev[w] = v
                queue.append(w)
    return comp


def main(argv):
    root = "."
    show_graph = False
    args = list(argv)
    while args:
        a = args.pop(0)
        if a == "--root" and args:
            root = args.pop(0)
        elif a == "--graph":
            show_graph = True
        else:
            print(__doc__.strip().splitlines()[-1], file=sys.stderr)
            return 2
    problems = []
    graph = {}
    files = sources(root)
    for src in files:
        mod = os.path.splitext(src)[0]
        layer = layer_of(mod)
        graph.setdefault(mod, set())
        if layer is None:
            problems.append("%s: not in a layer folder (common/<%s>/, master/, worker/, %s)" % (src, "|".join(LAYERS), ", ".join(d + "/" for d in SIDE)))
            continue
        with open(os.path.join(root, src), encoding="utf-8", errors="replace") as fh:
            for lineno, line in enumerate(fh, 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                target = resolve(root, src, m.group(1))
                if target is None:
                    problems.append('%s:%d: include "%s" names no file' % (src, lineno, m.group(1)))
                    continue
                tmod = os.path.splitext(target)[0]
                tlayer = layer_of(tmod)
                if tlayer is None:
                    problems.append('%s:%d: include "%s" is outside the layers' % (src, lineno, m.group(1)))
                    continue
                if tmod != mod:
                    graph[mod].add(tmod)
                if layer in SIDE or tlayer in SIDE:
                    if tlayer != layer and tlayer not in SIDE.get(layer, ()):
                        problems.append('%s:%d: include "%s" runs outside: %s may include only %s' % (
                            src, lineno, m.group(1), layer,
                            ", ".join(SIDE[layer] + (layer,)) if layer in SIDE else "the render stack"))
                    continue
                upward = RANK[tlayer] > RANK[layer]
                sideways = RANK[tlayer] == RANK[layer] and tlayer != layer
                if upward or sideways:
                    problems.append('%s:%d: include "%s" runs %s: %s may include only %s' % (
                        src, lineno, m.group(1), "upward" if upward else "sideways", layer,
                        " <- ".join(LAYERS[:RANK[layer] + 1] if layer in LAYERS else LAYERS) +
                        ("" if layer in LAYERS else " <- " + layer)))
    for comp in circles(graph):
        problems.append("circle between modules: %s (%d modules in it: %s)" % (
            " -> ".join(cycle_path(graph, comp)), len(comp), " ".join(comp)))
    if show_graph:
        for mod in sorted(graph):
            print("%s: %s" % (mod, " ".join(sorted(graph[mod]))))
    for p in problems:
        print("check_layers: " + p)
    edges = sum(len(v) for v in graph.values())
    print("check_layers: %d modules, %d arrows, %d problems" % (len(graph), edges, len(problems)))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
