"""mechdsl: an equation-based modelling language for holonomic rigid-body mechanics.

Python API::

    import mechdsl, mechdsl.examples
    m = mechdsl.load(mechdsl.examples.path("pendulum"))   # a file of yours, or mechdsl.loads(text)
    r = m.simulate(5.0, rtol=1e-8, atol=1e-10)
    r.t, r.q, r.qd, r["x"]
"""
import logging

from .diagnostics import Diagnostic, MechError, MechWarning, Span, UsageError
from .numbers import Quantity, deg, rad

__version__ = "0.1.0"

# Library messages (what is derived, loaded from a cache, compiled) go to the "mechdsl" logger;
# nothing is shown unless the application configures logging (``mech`` does: -v, -vv)
logging.getLogger(__name__).addHandler(logging.NullHandler())


# the documented submodules, imported on first use as scipy's are (``mechdsl.examples.path``
# after a plain ``import mechdsl``), so that ``import mechdsl`` stays light
_LAZY_SUBMODULES = frozenset({"examples", "sample", "sweep", "urdf", "dae", "analysis", "estimation", "export"})


def __getattr__(name):
    if name == "SimulationFailed":          # output.result imports numpy: only when asked
        from .output.result import SimulationFailed

        return SimulationFailed
    if name in _LAZY_SUBMODULES:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'mechdsl' has no attribute {name!r}")


def load(path, model=None, scene=None, **kw):
    """Load a model from a ``.mech`` file; returns a :class:`mechdsl.api.Model`.

    path
        The file (a str or a Path); the shipped examples: ``mechdsl.examples.path("pendulum")``.
    model, scene
        Which model or scene of the file (one at most).  Default: the file's first scene, else
        its last model, as ``mech simulate FILE`` chooses.  A scene brings its model, its
        overrides and its settings (stop time, tolerances, method).
    units
        False skips the dimensional analysis (default True).
    cache
        False neither reads nor writes the model cache (default True: a model loaded before
        comes back without parsing or deriving again; ``MECHDSL_CACHE`` says where).

    A model error raises :class:`mechdsl.MechError` (its text is the located message with the
    source line, as ``mech check`` prints it); an unknown model or scene name raises
    :class:`mechdsl.UsageError`.

        >>> import mechdsl, mechdsl.examples
        >>> m = mechdsl.load(mechdsl.examples.path("pendulum"), scene="Swing")
        >>> m
        <mechdsl.Model Pendulum, scene Swing: 1 coordinate>
        >>> r = m.simulate(2.0)          # a mechdsl.output.result.Result
    """
    from .api import load as _load

    return _load(path, model=model, scene=scene, **kw)


def loads(text, model=None, scene=None, filename="<string>", **kw):
    """Load a model from ``.mech`` source text; returns a :class:`mechdsl.api.Model`.

    ``filename`` names the text in messages (``<string>:3:12: error[E201]: ...``); ``model``,
    ``scene``, ``units`` and ``cache`` as for :func:`mechdsl.load`.

        >>> text = mechdsl.examples.path("pendulum").read_text()
        >>> mechdsl.loads(text, filename="pendulum.mech", model="PendulumLagrange").coordinates
        ('theta',)
    """
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


__all__ = ["load", "loads", "import_urdf", "table", "Diagnostic", "MechError", "MechWarning", "Span", "UsageError",
           "SimulationFailed", "Quantity", "deg",
           "rad", "__version__"]
