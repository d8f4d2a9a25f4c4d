"""The drawing: a matplotlib Figure (no pyplot) with one artist per drawable, moved to a frame
by :meth:`Stage.frame`.  Static parts (ground, rails, contact planes, the scale bar) are drawn
once; the moving artists are blitted onto that background, so a frame costs only them.

Views: ``xy``, ``xz``, ``yz`` (orthographic, 2D) and ``3d`` (an orthographic projection seen
from azimuth 35 deg, elevation 20 deg about the up direction); ``auto`` picks the plane in which
every moving point stays, else ``3d``.  Up is against gravity unless given (:mod:`.camera`).
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import UsageError
from .camera import DEFAULT_UP, screen_axes, up_label

VIEWS = ("auto", "xy", "xz", "yz", "3d")
INK = "#222222"
FLASH = "#ff7f0e"                 # an impact
TRACE = "#d62728"                 # the path of a traced point


def projection(view: str, up=DEFAULT_UP) -> np.ndarray:
    """(2, 3) matrix: world -> screen coordinates for a view with the given up direction."""
    if view not in VIEWS or view == "auto":
        raise UsageError(f"unknown view '{view}' (views: {', '.join(VIEWS)})")
    return screen_axes(view, up)[:2]


def detect_view(X: np.ndarray, anchors: list[int]) -> str:
    """The plane (xy, xz, yz) that holds every moving point at every frame, else '3d'."""
    if not anchors or not len(X):
        return "xy"
    A = X[:, :, anchors]
    spread = A.max(axis=(0, 2)) - A.min(axis=(0, 2))
    tol = 1e-9 * (1.0 + float(np.abs(A).max()))
    for view, normal in (("xy", 2), ("xz", 1), ("yz", 0)):
        if spread[normal] <= tol:
            return view
    return "3d"


BODY_KINDS = ("rod", "solid", "ellipsoid", "sphere", "point", "link")


GROUND = "#b0b0b0"                # shapes fixed on the world


def body_colours(geometry) -> dict[str, str]:
    """One colour per drawn body (its solids, dot and frame link share it), in order of drawing;
    shapes on the world are grey."""
    from ..output.plot import colours

    names: list[str] = []
    for it in geometry.items:
        if it.kind in BODY_KINDS and not it.extra.get("hidden") and it.body not in names and it.body != "world":
            names.append(it.body)
    return dict(zip(names, colours(len(names)))) | {"world": GROUND}


def check_view(view: str) -> str:
    if view not in VIEWS:
        raise UsageError(f"unknown view '{view}' (views: {', '.join(VIEWS)})")
    return view


class Blitted:
    """Frames by blitting: the static background is rendered once, then each frame restores it
    and draws only the moving artists.  Subclasses set ``figure``, ``t``, ``clock``, ``moving``
    and ``_background = None`` and implement ``_update(k)``."""

    def _update(self, k: int) -> None:
        raise TypeError(f"{type(self).__name__} does not move its artists")

    def frame(self, k: int) -> np.ndarray:
        """Move every artist to frame k and render; returns the RGBA pixels (H, W, 4)."""
        canvas = self.figure.canvas
        if self._background is None:
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.figure.bbox)
        canvas.restore_region(self._background)
        self._update(k)
        self.clock.set_text(f"t = {self.t[k]:7.3f} s")
        for a in sorted(self.moving, key=lambda a: a.get_zorder()):     # stable: ties keep their order
            self.figure.draw_artist(a)
        return np.asarray(canvas.buffer_rgba())

    def still(self, k: int):
        """The Figure showing frame k as ordinary (non-animated) artists: for display and savefig."""
        self._update(k)
        self.clock.set_text(f"t = {self.t[k]:.3f} s")
        for a in self.moving:
            a.set_animated(False)
        self._background = None
        return self.figure


class Stage(Blitted):
    """A Figure and its artists for frames k = 0..n_frames-1 of positions X (N, 3, K)."""

    def __init__(self, geometry, t, X, *, view="auto", up=None, events=(), title="", size=(480, 400), dpi=80):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from ..output.plot import new_figure

        check_view(view)
        self.view = detect_view(X, geometry.anchors) if view == "auto" else view
        self.t = np.asarray(t, float)
        self.geometry = geometry
        self.up = np.asarray(geometry.up if up is None else up, float)
        self.P = P = projection(self.view, self.up)
        self.S = np.einsum("ij,njk->nik", P, X)              # (N, 2, K) screen coordinates
        self.depth = None
        if self.view == "3d":                                 # distance towards the viewer, in [0, 1]
            D = np.einsum("j,njk->nk", np.cross(P[0], P[1]), X)
            self.depth = (D - D.min()) / max(float(np.ptp(D)), 1e-12)
        self.n_frames = len(self.t)
        self.figure = fig = new_figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        FigureCanvasAgg(fig)
        ax = self.ax = fig.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        self._limits(size)
        self.moving: list = []
        self.updaters: list = []
        palette = body_colours(geometry)
        self.swatch = list(palette.values()) + [INK, FLASH, TRACE, "#555555", "#999999", "#ffffff"]
        for it in geometry.items:
            colour = palette.get(it.body, INK) if it.kind in BODY_KINDS else INK
            getattr(self, "_add_" + it.kind)(it, colour)
        self._impacts(events)
        self.clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", ha="left", fontsize=11,
                             family="monospace", color=INK, animated=True)
        self.moving.append(self.clock)
        if title:
            ax.text(0.5, 0.97, title, transform=ax.transAxes, va="top", ha="center", fontsize=10, color="#555555")
        ax.text(0.98, 0.97, f"view {self.view}, {up_label(self.up)} up", transform=ax.transAxes, va="top", ha="right", fontsize=8,
                color="#777777")
        self._scale_bar()
        if self.view == "3d":
            self._triad(P)
        self._background = None

    # ------------------------------------------------------------------ frames
    def _update(self, k: int) -> None:
        for update in self.updaters:
            update(k)

    # ------------------------------------------------------------------ layout
    def _limits(self, size) -> None:
        S = self.S
        pad = []
        for it in self.geometry.items:
            if it.kind in ("plane", "trace"):
                continue
            pts = S[:, :, it.cols]
            r = it.radius
            pad.append((pts.min(axis=(0, 2)) - r, pts.max(axis=(0, 2)) + r))
        if not pad:
            lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
        else:
            lo = np.min([a for a, _ in pad], axis=0)
            hi = np.max([b for _, b in pad], axis=0)
        ext = max(float((hi - lo).max()), 1e-3)
        lo, hi = lo - 0.12 * ext, hi + 0.12 * ext
        lo[1] -= 0.06 * ext                          # room for the scale bar
        hi[1] += 0.08 * ext                          # and the time stamp
        c, half = (lo + hi) / 2, (hi - lo) / 2
        aspect = size[0] / size[1]
        if half[0] / half[1] < aspect:
            half[0] = half[1] * aspect
        else:
            half[1] = half[0] / aspect
        self.extent = ext
        self.ax.set_xlim(c[0] - half[0], c[0] + half[0])
        self.ax.set_ylim(c[1] - half[1], c[1] + half[1])

    def _scale_bar(self) -> None:
        x0, x1 = self.ax.get_xlim()
        y0, y1 = self.ax.get_ylim()
        target = (x1 - x0) / 5
        e = 10 ** math.floor(math.log10(target))
        length = max(m * e for m in (1, 2, 5) if m * e <= target)
        xa, ya = x1 - 0.04 * (x1 - x0) - length, y0 + 0.04 * (y1 - y0)
        self.ax.plot([xa, xa + length], [ya, ya], color=INK, lw=2, solid_capstyle="butt")
        self.ax.text(xa + length / 2, ya + 0.01 * (y1 - y0), f"{length:g} m", ha="center", va="bottom",
                     fontsize=8, color=INK)

    def _triad(self, P) -> None:
        """World axes x, y, z as seen in the 3d view (bottom left)."""
        x0, y0 = 0.09, 0.11
        for e, name in zip(np.eye(3), "xyz"):
            d = P @ e * 0.06
            self.ax.annotate("", xy=(x0 + d[0], y0 + d[1] * 1.2), xytext=(x0, y0), xycoords="axes fraction",
                             arrowprops={"arrowstyle": "->", "color": "#555555", "lw": 1.2})
            self.ax.text(x0 + d[0] * 1.35, y0 + d[1] * 1.2 * 1.35, name, transform=self.ax.transAxes,
                         ha="center", va="center", fontsize=8, color="#555555")

    def _by_depth(self, artist, it) -> None:
        """In 3d, bodies nearer the viewer are drawn over farther ones (z-order set per frame)."""
        if self.depth is None:
            return
        z = 3.0 + 0.99 * self.depth[:, it.cols].mean(axis=1)
        self.updaters.append(lambda k: artist.set_zorder(z[k]))

    def _line(self, **kw):
        (ln,) = self.ax.plot([], [], animated=True, **kw)
        self.moving.append(ln)
        return ln

    # ------------------------------------------------------------------ drawables
    def _add_rod(self, it, colour):
        ln = self._line(color=colour, lw=7, solid_capstyle="round", zorder=3)
        self._by_depth(ln, it)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: ln.set_data(pts[k, 0], pts[k, 1]))

    def _add_link(self, it, colour):
        ln = self._line(color=colour, lw=2, zorder=3)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: ln.set_data(pts[k, 0], pts[k, 1]))

    def _add_arm(self, it, colour):
        ln = self._line(color="#555555", lw=1.5, zorder=2)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: ln.set_data(pts[k, 0], pts[k, 1]))

    def _add_point(self, it, colour):
        if it.extra.get("hidden"):
            return
        ln = self._line(color=colour, marker="o", ms=10, ls="none", mec=INK, zorder=4)
        self._by_depth(ln, it)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: ln.set_data(pts[k, 0], pts[k, 1]))

    def _add_sphere(self, it, colour):
        from matplotlib.patches import Circle

        c = Circle((0, 0), it.radius, facecolor=colour, edgecolor=INK, lw=1, zorder=4, animated=True)
        self.ax.add_patch(c)
        self.moving.append(c)
        self._by_depth(c, it)
        pts = self.S[:, :, it.cols.start]
        self.updaters.append(lambda k: c.set_center((pts[k, 0], pts[k, 1])))

    def _add_solid(self, it, colour):
        from matplotlib.patches import Polygon

        poly = Polygon(np.zeros((3, 2)), closed=True, facecolor=colour, edgecolor=INK, lw=1, zorder=2,
                       animated=True)
        self.ax.add_patch(poly)
        self.moving.append(poly)
        self._by_depth(poly, it)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: poly.set_xy(_hull(pts[k].T)))

    def _add_ellipsoid(self, it, colour):
        from matplotlib.patches import Polygon

        # translucent: it stands for the inertia, not the body's form (its frame link shows through)
        poly = Polygon(np.zeros((3, 2)), closed=True, facecolor=colour, alpha=0.45, edgecolor=INK, lw=1, zorder=2,
                       animated=True)
        self.ax.add_patch(poly)
        self.moving.append(poly)
        self._by_depth(poly, it)
        S = self.S[:, :, it.cols]
        outline = ellipse_outline(S)
        axes = self._line(color=INK, lw=0.8, zorder=2)         # its principal axes: the spin shows
        self._by_depth(axes, it)
        c, tips = S[:, :, :1], S[:, :, 1:]
        nan = np.full_like(c, np.nan)
        path = np.concatenate([np.concatenate([2 * c - tips[:, :, i:i + 1], tips[:, :, i:i + 1], nan], axis=2)
                               for i in range(3)], axis=2)
        self.updaters.append(lambda k: (poly.set_xy(outline[k]), axes.set_data(path[k, 0], path[k, 1])))

    def _add_spring(self, it, colour, damper=False):
        ln = self._line(color="#555555", lw=1.5, zorder=2)
        pts = self.S[:, :, it.cols]
        width = 0.025 * self.extent
        path = (_damper if damper else _zigzag)(pts[:, :, 0], pts[:, :, 1], width)     # (N, 2, M)
        self.updaters.append(lambda k: ln.set_data(path[k, 0], path[k, 1]))

    def _add_damper(self, it, colour):
        self._add_spring(it, colour, damper=True)

    def _add_pin(self, it, colour):
        pts = self.S[:, :, it.cols.start]
        if it.extra.get("ground"):
            x, y = pts[0]
            s = 0.035 * self.extent
            self.ax.fill([x, x - s, x + s], [y, y - 1.6 * s, y - 1.6 * s], color="#bbbbbb", zorder=1)
            self.ax.plot([x - 1.6 * s, x + 1.6 * s], [y - 1.6 * s] * 2, color="#777777", lw=2, zorder=1)
        ln = self._line(color=INK, marker="o", ms=6, mfc="white", mew=1.5, ls="none", zorder=6)
        self.updaters.append(lambda k: ln.set_data([pts[k, 0]], [pts[k, 1]]))

    def _add_rail(self, it, colour):
        pts = self.S[:, :, it.cols.start]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        d = hi - lo
        n = np.linalg.norm(d)
        if n < 1e-12:
            return
        d = d / n * 0.1 * self.extent
        self.ax.plot([lo[0] - d[0], hi[0] + d[0]], [lo[1] - d[1], hi[1] + d[1]], color="#aaaaaa", lw=3, zorder=1)

    def _add_plane(self, it, colour):
        P = self.P
        n2 = P @ it.extra["normal"]
        base = P @ it.extra["base"]
        L = 2.0 * self.extent
        if np.linalg.norm(n2) > 0.999:                      # seen edge-on: a line with hatching
            tdir = np.array([-n2[1], n2[0]])
            a, b = base - L * tdir, base + L * tdir
            self.ax.plot([a[0], b[0]], [a[1], b[1]], color="#555555", lw=2, zorder=1)
            h = 0.025 * self.extent
            for s in np.linspace(-L, L, 161):
                p0 = base + s * tdir
                p1 = p0 - h * n2 - h * tdir
                self.ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color="#999999", lw=0.8, zorder=1)
            return
        u, v = P @ it.extra["u"], P @ it.extra["v"]
        corners = [base + L / 2 * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        from matplotlib.patches import Polygon

        self.ax.add_patch(Polygon(corners, closed=True, facecolor="#e8e8e8", edgecolor="#aaaaaa", zorder=0))

    def _add_ring(self, it, colour):
        from matplotlib.patches import Circle

        c = Circle((0, 0), it.radius, facecolor="none", edgecolor="#777777", lw=1.5, ls="--", zorder=1,
                   animated=True)
        self.ax.add_patch(c)
        self.moving.append(c)
        pts = self.S[:, :, it.cols.start]
        self.updaters.append(lambda k: c.set_center((pts[k, 0], pts[k, 1])))

    def _add_hoop(self, it, colour):
        ln = self._line(color="#999999", lw=2, zorder=1)
        pts = self.S[:, :, it.cols]
        self.updaters.append(lambda k: ln.set_data(pts[k, 0], pts[k, 1]))

    def _add_trace(self, it, colour):
        ln = self._line(color=TRACE, lw=1, zorder=2)
        pts = self.S[:, :, it.cols.start]
        self.updaters.append(lambda k: ln.set_data(pts[: k + 1, 0], pts[: k + 1, 1]))

    def _impacts(self, events) -> None:
        """Impacts flash at the touching points for a few frames (the cradle clicks)."""
        times = sorted(float(e["time"]) for e in events if e.get("kind") == "impact")
        if not times or self.n_frames < 2:
            return
        idx = np.searchsorted(self.t, times)                   # first frame at or after the impact
        flash = np.zeros(self.n_frames, bool)
        for i in idx:
            flash[i: i + 3] = True
        balls = [it for it in self.geometry.items if it.kind in ("sphere", "point", "rod") and not it.extra.get("hidden")]
        if not balls:
            return
        cols = [c for it in balls for c in range(it.cols.start, it.cols.stop)]
        pts = self.S[:, :, cols]
        ln = self._line(color=FLASH, marker="*", ms=16, ls="none", mec=INK, mew=0.5, zorder=7)
        word = self.ax.text(0.02, 0.90, "", transform=self.ax.transAxes, va="top", fontsize=10,
                            color=FLASH, animated=True)
        self.moving.append(word)

        def update(k):
            if flash[k]:
                ln.set_data(pts[k, 0], pts[k, 1])
                word.set_text("impact")
            else:
                ln.set_data([], [])
                word.set_text("")
        self.updaters.append(update)


def ellipse_outline(S: np.ndarray, n: int = 64) -> np.ndarray:
    """The projected outline of an ellipsoid from its screen centre and semi-axis ends
    (N, 2, 4): the image of the unit ball under W = [w1 w2 w3] is the ellipse c + L u, |u| = 1,
    with L L^T = W W^T (a 2x2 Cholesky factor).  Returns (N, n, 2)."""
    c = S[:, :, 0]
    W = S[:, :, 1:] - c[:, :, None]
    M = np.einsum("nik,njk->nij", W, W)
    l11 = np.sqrt(np.maximum(M[:, 0, 0], 0.0))
    l21 = np.divide(M[:, 1, 0], l11, out=np.zeros_like(l11), where=l11 > 0)
    l22 = np.sqrt(np.maximum(M[:, 1, 1] - l21 ** 2, 0.0))
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    u, v = np.cos(a), np.sin(a)
    x = c[:, 0, None] + l11[:, None] * u[None, :]
    y = c[:, 1, None] + l21[:, None] * u[None, :] + l22[:, None] * v[None, :]
    return np.stack([x, y], axis=2)


def _hull(p: np.ndarray) -> np.ndarray:
    """Convex hull of 2D points (monotone chain), counter-clockwise."""
    pts = sorted(map(tuple, np.round(p, 12)))
    if len(pts) <= 2:
        return np.array(pts + pts[:1])

    def half(points):
        h = []
        for q in points:
            while len(h) >= 2 and (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1]) - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(pts), half(pts[::-1])
    out = lower[:-1] + upper[:-1]
    return np.array(out if len(out) >= 2 else pts)


def _frame_dirs(a: np.ndarray, b: np.ndarray):
    d = b - a
    n = np.linalg.norm(d, axis=1, keepdims=True)
    u = np.divide(d, n, out=np.zeros_like(d), where=n > 1e-12)
    return d, np.stack([-u[:, 1], u[:, 0]], axis=1)


def _zigzag(a: np.ndarray, b: np.ndarray, w: float, coils: int = 8) -> np.ndarray:
    """A spring between a and b (N, 2 each) as a zig-zag: (N, 2, M), vectorized over frames."""
    d, nrm = _frame_dirs(a, b)
    s = np.concatenate([[0.0, 0.1], 0.1 + 0.8 * (np.arange(2 * coils) + 0.5) / (2 * coils), [0.9, 1.0]])
    off = np.concatenate([[0.0, 0.0], w * np.where(np.arange(2 * coils) % 2 == 0, 1.0, -1.0), [0.0, 0.0]])
    P = a[:, :, None] + d[:, :, None] * s[None, None, :] + nrm[:, :, None] * off[None, None, :]
    return P


def _damper(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """A dashpot: a rod from b ending in a plate inside a cup on a (NaN breaks between strokes)."""
    d, nrm = _frame_dirs(a, b)
    nan = np.full(2, np.nan)
    strokes = [((0, 0), (0.45, 0)), None, ((0.35, 1), (0.6, 1)), None, ((0.35, -1), (0.6, -1)), None,
               ((0.35, -1), (0.35, 1)), None, ((0.5, -0.7), (0.5, 0.7)), None, ((0.5, 0), (1.0, 0))]
    pts = []
    for st in strokes:
        if st is None:
            pts.append((nan[0], nan[1]))
        else:
            pts.extend(st)
    s = np.array([p[0] for p in pts])
    o = np.array([p[1] for p in pts]) * w
    return a[:, :, None] + d[:, :, None] * s[None, None, :] + nrm[:, :, None] * o[None, None, :]
