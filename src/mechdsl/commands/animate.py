"""``mech animate FILE -o OUT.gif|.html|.mp4``: simulate and draw the mechanism moving."""
from __future__ import annotations

import sys

from ._common import (
    add_cache_arg,
    add_force_arg,
    add_set_arg,
    add_target_args,
    load_model,
    number,
    target_line,
)

HELP = "simulate a model and write an animation of the mechanism (.gif, .html or .mp4)"


def add_parser(sub):
    from ..animate import VIEWS

    p = sub.add_parser("animate", help=HELP, description=HELP + ". Bodies are drawn from their shapes; plane "
                       "mechanisms are drawn in their plane, spatial ones projected (see docs/animate.md).")
    add_target_args(p, what="animate")
    add_cache_arg(p)
    p.add_argument("-o", "--output", metavar="OUT", required=True,
                   help="animation file: .gif, .html (play/pause and a scrubber) or .mp4 (needs ffmpeg)")
    p.add_argument("--fps", type=_num("--fps"), default=30.0, metavar="F", help="frames per second (default 30)")
    add_playback_args(p)
    p.add_argument("--view", default="auto", metavar="V",
                   help=f"{' | '.join(VIEWS)} (default auto: the plane of a plane mechanism, else 3d)")
    p.add_argument("--size", default="480x400", metavar="WxH", help="frame size in pixels (default 480x400)")
    add_set_arg(p)
    p.add_argument("--no-units", action="store_true", help="skip dimensional analysis")
    add_force_arg(p)
    return p


def add_playback_args(p) -> None:
    """--speed, --trail, --up, --t-end: shared with `mech view`."""
    p.add_argument("--speed", type=_num("--speed"), default=None, metavar="X",
                   help="model seconds per second of playback (default 1: real time; a run shorter than a "
                        "second is slowed down to play for at least 2 s, one longer than a minute sped up to "
                        "play for at most 60 s)")
    p.add_argument("--trail", action="append", default=[], metavar="POINT",
                   help="draw the path of a point (e.g. rod2.b); repeat for several")
    p.add_argument("--up", default=None, metavar="DIR",
                   help="the direction drawn up: x | y | z | -x | -y | -z (default: against gravity, else y)")
    p.add_argument("--t-end", type=_num("--t-end"), metavar="T", help="end time [s] (default: scene stop_time, else 10)")


def plan_frames(args, m, what: str = "animating"):
    """(frame times, speed) of a run of the loaded model: --t-end or the scene's stop time (else
    10 s), the start time, and the speed (--speed, else picked: said in a note)."""
    from ..animate import frame_times, pick_speed
    from ..diagnostics import UsageError

    t_end = args.t_end if args.t_end is not None else m.scene_settings.get("stop_time")
    if t_end is None:
        from ..simulation.settings import DEFAULT_T_END      # the one default end of a run

        t_end = DEFAULT_T_END
        args.out.note(f"no --t-end and no scene stop_time: {what} {t_end:g} s")
    t0 = float(m.scene_settings.get("start_time", 0.0))
    if not t_end > t0:
        raise UsageError(f"--t-end {t_end:g} must be after the start time {t0:g}")
    speed = args.speed
    if speed is None:
        speed = pick_speed(float(t_end) - t0)
        if speed != 1.0:
            pace = "slow motion" if speed < 1.0 else "fast motion"
            args.out.note(f"the run lasts {float(t_end) - t0:g} s: {what} it at --speed {speed:g} ({pace}, "
                          f"{(float(t_end) - t0) / speed:g} s of playback; --speed sets another)")
    return frame_times(t0, float(t_end), args.fps, speed), speed


def run(args) -> int:
    from ..animate import animate, check_output, check_view, up_vector

    check_output(args.output, args.force, args.fps)  # format, frame rate and place, before any work
    check_view(args.view)
    up = up_vector(args.up)
    size = _size(args.size)
    m = load_model(args)
    print(target_line(args, m))
    times, speed = plan_frames(args, m)
    from ..animate.geometry import build

    build(m.eom, traces=tuple(args.trail))            # bad --trail names fail before the run
    try:
        r = m.simulate(float(times[-1]), points=len(times))
    except KeyboardInterrupt:
        print("mech: interrupted during the simulation: nothing drawn, nothing written", file=sys.stderr)
        args.out.fail("interrupted", "interrupted during the simulation: nothing drawn, nothing written")
        return 130
    anim = animate(r, m, fps=args.fps, speed=speed, view=args.view, up=up, trails=args.trail, size=size)
    from ..animate.writer import AnimationInterrupted

    try:
        path = anim.save(args.output, overwrite=args.force)
    except AnimationInterrupted as e:
        print(f"wrote {e.path}: the first {e.frames} of {e.total} frames (interrupted)")
        print("mech: interrupted", file=sys.stderr)
        args.out.wrote(e.path)
        args.out.set(target=target_line(args, m), model=m.name, frames=e.frames, fps=args.fps, speed=speed)
        args.out.fail("interrupted", f"interrupted: the first {e.frames} of {e.total} frames written")
        return 130
    what = "bars of the coordinates (no bodies to draw)" if anim.view == "bars" else f"view {anim.view}"
    pace = "" if speed == 1.0 else f" at speed {speed:g}"
    print(f"wrote {path}: {len(anim)} frames at {args.fps:g} fps{pace}, {anim.times[-1] - anim.times[0]:g} s of model "
          f"time, {what}")
    args.out.wrote(path)
    args.out.set(target=target_line(args, m), model=m.name, frames=len(anim), fps=args.fps, speed=speed,
                 view=anim.view, t_start=float(anim.times[0]), t_end=float(anim.times[-1]),
                 success=r.failure is None)
    if r.failure is not None:
        print(f"mech: error: {r.failure}; animated up to t = {r.t[-1]:.6g}", file=sys.stderr)
        args.out.fail("simulation", f"{r.failure}; animated up to t = {r.t[-1]:.6g}")
        return 1
    return 0


def _num(option):
    def parse(text):
        import argparse

        from ..diagnostics import UsageError

        try:
            return number(text, what=option)
        except UsageError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return parse


def _size(text: str) -> tuple[int, int]:
    from ..diagnostics import UsageError

    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise UsageError(f"--size expects WIDTHxHEIGHT in pixels, e.g. 480x400 (got {text!r})") from None
    if not (32 <= w <= 4000 and 32 <= h <= 4000):
        raise UsageError(f"--size {w}x{h}: each side must be between 32 and 4000 pixels")
    return w, h
