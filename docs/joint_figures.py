"""Draw the sign convention of every joint kind (docs/figures/joint_*.png) from mechdsl itself.

Each picture is computed, not drawn by hand: a small model with the joint and a marker body is
derived by mechdsl, and the marker's points are evaluated at the zero configuration (grey,
dashed) and at a positive value of one joint variable (blue), so the pictures show what the
code does. Run from the repository root:

    python docs/joint_figures.py            # writes docs/figures/joint_<kind>.png

The table in docs/language.md ("Sign conventions of the joints") refers to these files.
"""
from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import mechdsl  # noqa: E402

# A marker body: a box whose frame origin is the joint's child point, with points along its
# body axes (x red, y green, z blue) so rotations and translations are visible.
MARKER = """
  Body b(m = 1, I = diagonal({0.1, 0.1, 0.1}));
  Point bx(body = b, r = {1, 0, 0});
  Point by(body = b, r = {0, 1, 0});
  Point bz(body = b, r = {0, 0, 1});
"""

# kind -> (joint declaration, [(variable, value shown)], view: "xy" or "3d")
JOINTS = {
    "revolute": ('Revolute j(parent = world, child = b, axis = {0, 0, 1});', [("j.phi", 0.6)], "xy"),
    "prismatic": ('Prismatic j(parent = world, child = b, axis = {1, 0, 0});', [("j.s", 0.6)], "xy"),
    "cylindrical": ('Cylindrical j(parent = world, child = b, axis = {0, 0, 1});', [("j.phi", 0.6), ("j.s", 0.6)], "3d"),
    "planar": ('Planar j(parent = world, child = b, axis = {0, 0, 1});', [("j.x", 0.6), ("j.y", 0.6), ("j.phi", 0.6)], "xy"),
    "spherical": ('Spherical j(parent = world, child = b);', [("j.phi", 0.6), ("j.theta", 0.6), ("j.psi", 0.6)], "3d"),
    "free": ('Free j(child = b);', [("j.x", 0.6), ("j.y", 0.6), ("j.z", 0.6), ("j.phi", 0.6), ("j.theta", 0.6),
                                    ("j.psi", 0.6)], "3d"),
}


def marker_points(kind: str):
    decl, variables, view = JOINTS[kind]
    m = mechdsl.loads(f"model M\n{MARKER}  {decl}\nend M;\n")
    e = m.eom
    names = ["b", "bx", "by", "bz"]
    f = ca.Function("p", [e.q, e.t, e.p], [ca.horzcat(*[e.point_position(n) for n in names])])

    def at(q):
        return np.array(f(q, 0.0, e.param_values), float)

    q0 = np.zeros(len(e.coords))
    frames = []
    for var, val in variables:
        q = q0.copy()
        q[e.coords.index(var)] = val
        frames.append((var, val, at(q)))
    return at(q0), frames, view


def draw(kind: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    zero, frames, view = marker_points(kind)
    n = len(frames)
    fig = plt.figure(figsize=(2.6 * n, 2.8))
    colors = ("tab:red", "tab:green", "tab:blue")
    for k, (var, val, P) in enumerate(frames):
        ax = fig.add_subplot(1, n, k + 1, projection="3d" if view == "3d" else None)
        for pts, style, alpha in ((zero, "--", 0.5), (P, "-", 1.0)):
            o = pts[:, 0]
            for i in range(3):
                if view == "xy" and i == 2:
                    continue
                e = pts[:, i + 1]
                xs = [o[0], e[0]], [o[1], e[1]], [o[2], e[2]]
                c = "grey" if style == "--" else colors[i]
                if view == "3d":
                    ax.plot(*xs, style, color=c, alpha=alpha, lw=2)
                else:
                    ax.plot(xs[0], xs[1], style, color=c, alpha=alpha, lw=2)
        if view == "3d":
            for i, lab in enumerate("xyz"):
                d = np.eye(3)[i] * 1.4
                ax.plot([0, d[0]], [0, d[1]], [0, d[2]], ":", color="k", lw=0.8)
                ax.text(*(d * 1.05), lab, fontsize=8)
            ax.set_xlim(-1, 1.6), ax.set_ylim(-1, 1.6), ax.set_zlim(-1, 1.6)
            ax.view_init(elev=20, azim=35)
            ax.set_xticks([]), ax.set_yticks([]), ax.set_zticks([])
        else:
            ax.axhline(0, color="k", lw=0.6, ls=":"), ax.axvline(0, color="k", lw=0.6, ls=":")
            ax.set_xlim(-1.3, 1.9), ax.set_ylim(-1.3, 1.9), ax.set_aspect("equal")
            ax.set_xlabel("x", fontsize=8), ax.set_ylabel("y", fontsize=8)
            ax.tick_params(labelsize=7)
        ax.set_title(f"{var} = +{val}", fontsize=9)
    fig.suptitle(f"{kind}: grey dashed = zero, colour = positive (body x red, y green, z blue)", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=80, metadata={"Software": None})
    plt.close(fig)


def cart_pole_tips(axis: str, theta: float = 0.3):
    """(hinge, tip) of models/cart_pole.mech with the hinge axis `axis`, at x = 0 and theta."""
    text = (ROOT / "models" / "cart_pole.mech").read_text().replace("axis = {0, 0, 1}, phi = theta", f"axis = {axis}, phi = theta")
    e = mechdsl.loads(text, model="CartPole").eom
    f = ca.Function("p", [e.q, e.t, e.p], [ca.horzcat(e.point_position("pole.a"), e.point_position("pole.b"))])
    q = np.zeros(len(e.coords))
    q[e.coords.index("theta")] = theta
    return np.array(f(q, 0.0, e.param_values), float)


def draw_cart_pole(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(5.2, 2.8))
    for ax, axis in zip(axes, ("{0, 0, 1}", "{0, 0, -1}")):
        P = cart_pole_tips(axis)
        ax.add_patch(plt.Rectangle((-0.2, -0.1), 0.4, 0.2, color="0.8"))
        ax.plot([P[0, 0], P[0, 0]], [P[1, 0], P[1, 0] + 1], "--", color="grey")
        ax.plot(P[0], P[1], "-", color="tab:blue", lw=3)
        ax.set_xlim(-0.8, 0.8), ax.set_ylim(-0.2, 1.2), ax.set_aspect("equal")
        ax.set_title(f"axis = {axis}: theta = +0.3", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=80, metadata={"Software": None})
    plt.close(fig)


def main() -> None:
    out = ROOT / "docs" / "figures"
    for kind in JOINTS:
        path = out / f"joint_{kind}.png"
        draw(kind, path)
        print("wrote", path.relative_to(ROOT))
    path = out / "joint_cart_pole_axis.png"
    draw_cart_pole(path)
    print("wrote", path.relative_to(ROOT))


if __name__ == "__main__":
    main()
