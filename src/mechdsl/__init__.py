"""mechdsl: an equation-based modelling language for holonomic rigid-body mechanics.

Python API::

    import mechdsl
    m = mechdsl.load("models/pendulum.mech")          # or mechdsl.loads(text)
    r = m.simulate(5.0, rtol=1e-8, atol=1e-10)
    r.t, r.q, r.qd, r["x"]
"""
from .diagnostics import Diagnostic, MechError, Span, UsageError

__version__ = "0.1.0"


def load(path, model=None, scene=None, **kw):
    from .api import load as _load

    return _load(path, model=model, scene=scene, **kw)


def loads(text, model=None, scene=None, filename="<string>", **kw):
    from .api import loads as _loads

    return _loads(text, model=model, scene=scene, filename=filename, **kw)


def import_urdf(path, *, floating=False, measured_inertia=False, package_dirs=None, skip_missing_meshes=False):
    """The .mech text of the robot described by a URDF file (mechdsl.urdf; docs/import.md)."""
    from .urdf import import_urdf as _import

    return _import(path, floating=floating, measured_inertia=measured_inertia, package_dirs=package_dirs,
                   skip_missing_meshes=skip_missing_meshes)


def table(times, values, hold="zoh"):
    """Samples of an input signal for ``simulate(inputs={name: table(...)})``: hold = "zoh"
    (zero-order hold) or "linear" (mechdsl.simulation.drive)."""
    from .simulation.drive import table as _table

    return _table(times, values, hold)


__all__ = ["load", "loads", "import_urdf", "table", "Diagnostic", "MechError", "Span", "UsageError", "__version__"]
