"""Minimum vertex cover size of small graphs, for the CG heuristic of CBS (Felner et al. 2018).

Exact branching (a vertex of maximum degree is in the cover, or all its neighbours are) on each
connected component up to ``EXACT_LIMIT`` vertices; larger components get the size of a greedy
maximal matching, which is still a lower bound and so keeps the heuristic admissible.
"""

from __future__ import annotations

from collections.abc import Iterable

EXACT_LIMIT = 16


def min_vertex_cover(edges: Iterable[tuple[int, int]]) -> int:
    """Size of a minimum vertex cover (a lower bound of it for components above the limit)."""
    adj: dict[int, set[int]] = {}
    for a, b in sorted(set(edges)):
        adj.setdefault(a, set()).add(b)
        adj.setdefault(b, set()).add(a)
    total = 0
    seen: set[int] = set()
    for v in sorted(adj):
        if v in seen:
            continue
        comp = {v}
        stack = [v]
        while stack:
            for w in adj[stack.pop()]:
                if w not in comp:
                    comp.add(w)
                    stack.append(w)
        seen |= comp
        sub = {u: adj[u] & comp for u in comp}
        total += _exact(sub) if len(comp) <= EXACT_LIMIT else _matching(sub)
    return total


def _exact(adj: dict[int, set[int]]) -> int:
    live = {u: s for u, s in adj.items() if s}
    if not live:
        return 0
    v = max(sorted(live), key=lambda u: len(live[u]))
    if len(live[v]) == 1:
        # every vertex has degree one: the graph is a matching
        return len(live) // 2

    def without(removed: set[int]) -> dict[int, set[int]]:
        return {u: s - removed for u, s in live.items() if u not in removed}

    nbrs = live[v]
    return min(1 + _exact(without({v})), len(nbrs) + _exact(without(nbrs | {v})))


def _matching(adj: dict[int, set[int]]) -> int:
    matched: set[int] = set()
    size = 0
    for u in sorted(adj):
        if u in matched:
            continue
        for w in sorted(adj[u]):
            if w not in matched:
                matched |= {u, w}
                size += 1
                break
    return size
