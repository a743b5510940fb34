"""Slow, obviously correct reference of the run-time simplification filter (paper 4.2)."""

from __future__ import annotations


def naive_filter(batches, anc):
    """Yield (faces, tets) per batch as lists of tuples, using dicts and sets."""
    arrived = set()
    waiting = []  # [item, set of missing ancestors, kind]
    for b in batches:
        arrived.update(range(b.first, b.first + len(b.points)))
        out = {"face": [], "tet": []}
        still = []
        for item, missing, kind in waiting:  # release what this batch completes
            missing -= arrived
            (still if missing else out[kind]).append((item, missing, kind) if missing else item)
        waiting = still
        for kind, items in (("face", b.boundary), ("tet", b.tets)):
            for it in items:
                mapped = tuple(int(anc[v]) for v in it)
                if len(set(mapped)) < len(mapped):
                    continue
                missing = set(mapped) - arrived
                if missing:
                    waiting.append((mapped, missing, kind))
                else:
                    out[kind].append(mapped)
        yield out["face"], out["tet"]
    assert not waiting
