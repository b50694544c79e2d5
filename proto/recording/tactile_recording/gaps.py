"""The gaps between the bodies of a recorded session: for each state frame, per pair of bodies, the smallest
signed distance from a surface vertex of one to the closed surface of the other (negative: inside it, how
deep), both ways; the surface each body is touched as (its fine surface when it has one, else its frame
surface).

    from tactile_recording import open_recording
    from tactile_recording.gaps import gaps
    result = gaps(open_recording("session.mcap"), every=10)
    result.pairs[("organ", "bed")].smallest_m

A vertex is inside a surface when the surface's winding number about it is above one half (the sum of the
solid angles of its triangles seen from the vertex over 4 pi: 1 inside a closed surface, 0 outside, and a
smooth measure between for a surface that is not quite closed); its distance is to the nearest triangle.
Only vertices within `near` of the other body's box are measured: a pair farther apart than that in a frame
has no gap in it (NaN in the table).
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
from typing import Any

import numpy as np

from .reader import Recording

# Points per block of the vectorised distance and winding sums (a block's arrays are points x triangles).
_BLOCK = 256


def point_triangle_distances(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The distance from each point (m x 3) to each triangle (k x 3 corners x 3) [m], m x k; a degenerate
    triangle's is to its nearest edge."""
    p = points[:, None, :]
    a, b, c = (triangles[None, :, i, :] for i in range(3))
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = n / area2[..., None]
    plane = np.abs(np.einsum("...i,...i->...", p - a, unit))
    # Over the triangle: p on the inner side of each edge's plane through the normal.
    inside = np.ones(plane.shape, dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("...i,...i->...", np.cross(v - u, p - u), n) >= 0
    inside &= area2 > 0

    def segment(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        e = v - u
        length2 = np.einsum("...i,...i->...", e, e)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip(np.einsum("...i,...i->...", p - u, e) / length2, 0.0, 1.0)
        t = np.where(length2 > 0, t, 0.0)
        return np.linalg.norm(p - (u + t[..., None] * e), axis=-1)

    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, plane, edges)


def winding_numbers(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The winding number of the surface `triangles` (k x 3 x 3, outward by the right hand) about each point
    (m x 3): the sum of the triangles' signed solid angles (Van Oosterom and Strackee) over 4 pi."""
    total = np.zeros(len(points))
    for s in range(0, len(points), _BLOCK):
        p = points[s:s + _BLOCK, None, :]
        a, b, c = (triangles[None, :, i, :] - p for i in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("...i,...i->...", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("...i,...i->...", a, b) * lc + np.einsum("...i,...i->...", b, c) * la
               + np.einsum("...i,...i->...", c, a) * lb)
        total[s:s + _BLOCK] = (2.0 * np.arctan2(det, den)).sum(axis=1)
    return total / (4.0 * math.pi)


def signed_gaps(points: np.ndarray, triangles: np.ndarray, near: float) -> np.ndarray:
    """Each point's signed distance to the closed surface `triangles` [m]: negative inside; NaN for a point
    farther than `near` from every triangle (only the triangles within `near` of the points' box are
    searched)."""
    out = np.full(len(points), np.nan)
    if not len(points) or not len(triangles):
        return out
    lo, hi = points.min(axis=0) - near, points.max(axis=0) + near
    keep = np.all((triangles.max(axis=1) >= lo) & (triangles.min(axis=1) <= hi), axis=1)
    nearby = triangles[keep]
    if not len(nearby):
        return out
    for s in range(0, len(points), _BLOCK):
        d = point_triangle_distances(points[s:s + _BLOCK], nearby).min(axis=1)
        out[s:s + _BLOCK] = np.where(d <= near, d, np.nan)
    close = np.flatnonzero(np.isfinite(out))
    if len(close):
        inside = winding_numbers(points[close], triangles) > 0.5
        out[close] = np.where(inside, -out[close], out[close])
    return out


@dataclasses.dataclass
class PairGaps:
    """One pair of bodies over the frames measured."""
    smallest_m: float = math.nan   # the smallest gap over them [m] (NaN: never within `near`)
    at_s: float = math.nan         # the sim time of that frame [s]
    into: str = ""                 # the body the vertex was inside (or nearest) there
    frames_inside: int = 0         # frames with some vertex inside the other body


@dataclasses.dataclass
class Gaps:
    """What gaps() found: per frame measured, (sim time [s], {pair: smallest gap [m]}); per pair its least."""
    bodies: list[str] = dataclasses.field(default_factory=list)
    frames: list[tuple[float, dict[tuple[str, str], float]]] = dataclasses.field(default_factory=list)
    pairs: dict[tuple[str, str], PairGaps] = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)


def _text(name: Any) -> str:
    return name.decode() if isinstance(name, bytes) else str(name or "")


class _Surfaces:
    """A scene's bodies as the surfaces contact meets: per body, where its vertices come from and its
    triangles (in those vertices)."""

    def __init__(self, scene: Any) -> None:
        self.names = [_text(b.name) for b in scene.bodies or []]
        e = scene.embedded
        fine = (e is not None and e.carriers is not None and e.weights is not None and e.triangles is not None)
        self.carriers = np.asarray(e.carriers, np.int64).reshape(-1, 4) if fine else None
        self.weights = np.asarray(e.weights, np.float64).reshape(-1, 4) if fine else None
        frame_triangles = np.asarray(scene.triangles if scene.triangles is not None else [], np.int64).reshape(-1, 3)
        fine_triangles = np.asarray(e.triangles, np.int64).reshape(-1, 3) if fine else None
        # Per body: (fine?, its vertex ids, its triangles in them).
        self.parts: list[tuple[bool, np.ndarray, np.ndarray]] = []
        for b in scene.bodies or []:
            if fine and b.fineTriangleEnd > b.fineTriangleBegin:
                assert fine_triangles is not None
                tris = fine_triangles[b.fineTriangleBegin:b.fineTriangleEnd]
                self.parts.append((True, np.arange(b.fineVertexBegin, b.fineVertexEnd), tris))
            else:
                tris = frame_triangles[b.triangleBegin:b.triangleEnd]
                self.parts.append((False, np.arange(b.vertexBegin, b.vertexEnd), tris))

    def place(self, x: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per body, its vertices (n x 3) and triangles (k x 3 x 3) at frame positions x."""
        out = []
        fine_x = None
        for fine, ids, tris in self.parts:
            if fine:
                if fine_x is None:
                    assert self.carriers is not None and self.weights is not None
                    fine_x = np.einsum("pk,pki->pi", self.weights, x[self.carriers])
                out.append((fine_x[ids], fine_x[tris]))
            else:
                out.append((x[ids], x[tris]))
        return out


def _pair_gaps(names: list[str], placed: list[tuple[np.ndarray, np.ndarray]], near: float
               ) -> dict[tuple[str, str], tuple[float, str]]:
    """Per pair of bodies, the smallest signed gap both ways (NaN: none within `near`) and the body a vertex
    was inside or nearest to there."""
    out = {}
    for i in range(len(placed)):
        for j in range(i + 1, len(placed)):
            least, into = math.nan, ""
            for a, b in ((i, j), (j, i)):
                vertices, _ = placed[a]
                _, tris = placed[b]
                if not len(vertices) or not len(tris):
                    continue
                lo, hi = tris.reshape(-1, 3).min(axis=0) - near, tris.reshape(-1, 3).max(axis=0) + near
                g = signed_gaps(vertices[np.all((vertices >= lo) & (vertices <= hi), axis=1)], tris, near)
                if np.isfinite(g).any() and not (np.nanmin(g) >= least):
                    least, into = float(np.nanmin(g)), names[b]
            out[(names[i], names[j])] = (least, into)
    return out


def frame_gaps(scene: Any, positions: np.ndarray, near: float = 0.005) -> dict[tuple[str, str], float]:
    """One frame's smallest signed gap per pair of `scene`'s bodies [m], its frame vertices at `positions`
    (n x 3, or flat)."""
    s = _Surfaces(scene)
    placed = s.place(np.asarray(positions, np.float64).reshape(-1, 3))
    return {pair: g for pair, (g, _) in _pair_gaps(s.names, placed, near).items()}


def gaps(recording: Recording, every: int = 1, near: float = 0.005) -> Gaps:
    """The smallest signed gap between each pair of bodies in every `every`th state frame of `recording`
    (each frame measured against its own scene), both ways [m]; NaN where none of the pair's vertices is
    within `near` [m] of the other's surface."""
    if every < 1:
        raise ValueError(f"every is {every}: it counts state frames, from 1")
    result = Gaps()
    scenes: dict[int, Any] = {}
    latest = None
    surfaces: dict[int, _Surfaces] = {}
    seen = 0
    for topic, _, envelope in recording.decoded(["/scene", "/state"]):
        m = envelope.message
        if topic == "/scene":
            scenes[m.sceneId] = latest = m
            surfaces.pop(m.sceneId, None)
            continue
        scene = scenes.get(m.sceneId, latest)
        if scene is None or len(scene.bodies or []) < 2:
            continue
        seen += 1
        if (seen - 1) % every:
            continue
        if m.sceneId not in surfaces:
            surfaces[m.sceneId] = _Surfaces(scene)
            for name in surfaces[m.sceneId].names:
                if name not in result.bodies:
                    result.bodies.append(name)
        s = surfaces[m.sceneId]
        x = np.asarray(m.positions if m.positions is not None else [], np.float64).reshape(-1, 3)
        try:
            placed = s.place(x)
        except IndexError:
            result.notes.append(f"a state at t = {m.simTime:.4f} s holds fewer vertices than its scene's bodies: "
                                "skipped")
            continue
        row: dict[tuple[str, str], float] = {}
        for pair, (least, into) in _pair_gaps(s.names, placed, near).items():
            row[pair] = least
            p = result.pairs.setdefault(pair, PairGaps())
            if least < 0:
                p.frames_inside += 1
            if math.isfinite(least) and not (least >= p.smallest_m):
                p.smallest_m, p.at_s, p.into = least, float(m.simTime), into
        result.frames.append((float(m.simTime), row))
    if not result.frames:
        result.notes.append("no state frame of a scene with two bodies or more: nothing to measure")
    return result


def write_csv(result: Gaps, path: str | pathlib.Path) -> int:
    """gaps.csv: sim_time_s, then per pair a column '<a>|<b>_gap_m' (the smallest signed gap, empty when
    farther than `near`). Returns the rows written."""
    pairs = list(result.pairs)
    lines = [",".join(["sim_time_s"] + [f"{a}|{b}_gap_m" for a, b in pairs])]
    for t, row in result.frames:
        cells = [repr(t)] + ["" if not math.isfinite(row.get(p, math.nan)) else repr(row[p]) for p in pairs]
        lines.append(",".join(cells))
    pathlib.Path(path).write_text("\n".join(lines) + "\n")
    return len(result.frames)


def summarize(result: Gaps) -> str:
    """The text `tactile-recording gaps` prints: per pair, its smallest gap, when, and into which body."""
    lines = [f"frames measured: {len(result.frames)}"]
    for (a, b), p in result.pairs.items():
        if not math.isfinite(p.smallest_m):
            lines.append(f"{a} and {b}: never within reach of each other")
            continue
        where = "a vertex inside" if p.smallest_m < 0 else "the nearest vertex outside"
        lines.append(f"{a} and {b}: smallest gap {p.smallest_m * 1e3:+.4f} mm at t = {p.at_s:.4f} s "
                     f"({where} {p.into}); {p.frames_inside} of {len(result.frames)} frames with a vertex of "
                     "one inside the other")
    return "\n".join(lines)


__all__ = ["Gaps", "PairGaps", "frame_gaps", "gaps", "point_triangle_distances", "signed_gaps", "summarize",
           "winding_numbers", "write_csv"]
