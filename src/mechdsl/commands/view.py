"""``mech view FILE -o OUT.html``: simulate and write the interactive 3-D view (three.js)."""
from __future__ import annotations

import sys

from ._common import add_cache_arg, add_force_arg, add_set_arg, add_target_args, load_model, target_line
from .animate import _num, add_playback_args, plan_frames

HELP = "simulate a model and write an interactive 3-D view of it (one self-contained .html page)"


def add_parser(sub):
    p = sub.add_parser("view", help=HELP, description=HELP + ": turn, zoom and pan the scene with the mouse; "
                       "play, pause, scrub and change the speed (see docs/animate.md).")
    add_target_args(p, what="view")
    add_cache_arg(p)
    p.add_argument("-o", "--output", metavar="OUT.html", required=True, help="the page to write")
    p.add_argument("--fps", type=_num("--fps"), default=30.0, metavar="F",
                   help="frames stored per second of playback (default 30; the page interpolates between them)")
    add_playback_args(p)
    p.add_argument("--still", action="store_true", help="no simulation: the mechanism at its start values")
    add_set_arg(p)
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    add_force_arg(p)
    return p


def run(args) -> int:
    from ..animate import up_vector
    from ..animate.geometry import build
    from ..view import check_output, still, view

    out = args.out
    check_output(args.output, args.force)             # name and place, before any work
    up = up_vector(args.up)
    m = load_model(args)
    target = target_line(args, m)
    print(target)
    build(m.eom, traces=tuple(args.trail))             # bad --trail names fail before the run
    if args.still:
        v = still(m, up=up, trails=args.trail)
        path = v.save(args.output, overwrite=args.force)
        out.wrote(path)
        out.set(**_result(target, m, v, still=True, fps=None, speed=None, success=True))
        print(f"wrote {path}: {m.name} at its start values, {_what(v)}")
        return 0
    times, speed = plan_frames(args, m, what="viewing")
    r = m.simulate(float(times[-1]), points=len(times))
    v = view(r, m, fps=args.fps, speed=speed, up=up, trails=args.trail)
    path = v.save(args.output, overwrite=args.force)
    out.wrote(path)
    out.set(**_result(target, m, v, still=False, fps=args.fps, speed=speed, success=r.failure is None))
    pace = "" if speed == 1.0 else f" at speed {speed:g}"
    print(f"wrote {path}: {len(v)} frames for {args.fps:g} fps{pace}, {v.times[-1] - v.times[0]:g} s of model time, "
          f"{_what(v)}")
    if r.failure is not None:
        print(f"mech: error: {r.failure}; viewed up to t = {r.t[-1]:.6g}", file=sys.stderr)
        out.fail("simulation", f"{r.failure}; viewed up to t = {r.t[-1]:.6g}")
        return 1
    return 0


def _result(target: str, m, v, *, still: bool, fps, speed, success: bool) -> dict:
    """The --json result of a page: what it shows and over which model times [s]."""
    times = v.times
    return {"target": target, "model": m.name, "still": still, "mode": v.mode,
            "up": v.data.get("up_label") if v.mode == "3d" else None, "frames": len(v), "fps": fps,
            "speed": speed, "t_start": float(times[0]), "t_end": float(times[-1]), "success": success}


def _what(v) -> str:
    if v.mode == "bars":
        return "bars of the coordinates (no bodies to draw)"
    return f"{v.data['up_label']} up"
