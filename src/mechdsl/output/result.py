"""Simulation results (a contract relied upon by users and other tools).

``r.t`` (n_t,), ``r.q`` and ``r.qd`` (n_t, n) in coordinate order, ``r.coordinates`` the
names, ``r[name]`` any recorded signal (a coordinate, ``der(name)``, an output, an energy,
an invariant, a drift measure), ``r.to_csv(path)``, ``r.stats`` (one schema for every run:
steps, rhs_evals, jac_evals, rejected_steps, events, points, cpu_time, wall_time,
energy_drift(_relative), invariant_drift, constraint_drift; see
mechdsl.simulation.accuracy), ``r.metadata["run"]`` (what ran: problem kind, formulation,
integrator, method, tolerances, compiled), ``r.success``/``r.message``/``r.failure`` and
``r.events``.
"""
from __future__ import annotations

import math
import re
import sys
from dataclasses import field
from typing import Any

from .fileio import write_atomic_group
from ..model.records import record
from ..model.names import split_state


@record(frozen=False)
class Failure:
    """Why and where a run stopped early."""

    time: float
    cause: str
    detail: str = ""

    def __str__(self) -> str:
        return f"simulation failed at t = {self.time:.6g}: {self.cause}" + (f" ({self.detail})" if self.detail else "")


@record(frozen=False)
class Result:
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    coordinates: tuple[str, ...]
    signals: dict[str, np.ndarray] = field(default_factory=dict)   # outputs, energies, invariants, drift
    stats: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)         # model, options, method and why, versions
    events: list[dict[str, Any]] = field(default_factory=list)
    failure: Failure | None = None

    def __repr__(self) -> str:
        """One line: what ran, over which times, how it went (the arrays: ``r.t``, ``r.q``, ...;
        in a notebook the HTML display shows a table and a plot)."""
        m = self.metadata or {}
        scene = m.get("scene") or getattr(getattr(getattr(self, "source_model", None), "scene", None), "name", None)
        who = str(m.get("model", "?")) + (f", scene {scene}" if scene else "")
        n = len(self.coordinates)
        span = f"t = {self.t[0]:g} .. {self.t[-1]:g} s, {len(self.t)} points" if len(self.t) else "no points"
        parts = [span, f"{n} coordinate{'' if n == 1 else 's'}"]
        if m.get("method"):
            parts.append(f"method {m['method']}")
        drift = self.stats.get("energy_drift_relative") if isinstance(self.stats, dict) else None
        if drift is not None:
            parts.append(f"relative energy {'drift' if m.get('conservative', True) else 'change'} {drift:.2g}")
        if self.events:
            parts.append(f"{len(self.events)} event{'' if len(self.events) == 1 else 's'}")
        state = "ok" if self.failure is None else f"FAILED at t = {self.failure.time:.6g}: {self.failure.cause}"
        return f"<mechdsl.Result {who}: {', '.join(parts)}; {state}>"

    def _repr_html_(self):                      # notebook displays (mechdsl.output.display)
        from .display import result_html

        return result_html(self)

    def _repr_markdown_(self):
        from .display import result_markdown

        return result_markdown(self)

    # -- access -----------------------------------------------------------------------
    @property
    def success(self) -> bool:
        """True when the run reached its end time (``failure`` is None)."""
        return self.failure is None

    @property
    def ok(self) -> bool:
        """The run succeeded and nothing says its numbers are less accurate than its tolerance
        asks (the error estimate and the invariants' drift within what the tolerance suggests:
        ``metadata["accuracy"]["warning"]``)."""
        acc = self.metadata.get("accuracy") if isinstance(self.metadata, dict) else None
        return self.failure is None and not (acc or {}).get("warning")

    def raise_for_failure(self, accuracy: bool = False) -> "Result":
        """Raise :class:`SimulationFailed` when the run failed (with ``accuracy=True`` also when it is
        not ``ok``: the accuracy warning); returns the Result otherwise, so that
        ``r = m.simulate(5).raise_for_failure()`` reads well."""
        if self.failure is not None:
            raise SimulationFailed(str(self.failure), self)
        if accuracy and not self.ok:
            raise SimulationFailed(self.metadata["accuracy"]["warning"], self)
        return self

    @property
    def message(self) -> str:
        """"ok", or why and where the run stopped (``str(failure)``)."""
        return "ok" if self.failure is None else str(self.failure)

    @property
    def columns(self) -> list[str]:
        """The names of the recorded signals in CSV order: time, the coordinates, their speeds
        ``der(c)``, then outputs, energies, invariants and drift measures (``r[name]``)."""
        return (["time"] + list(self.coordinates) + [f"der({c})" for c in self.coordinates]
                + list(self.signals))

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("time", "t"):
            return self.t
        key = self._resolve(name)
        if key is None:
            raise KeyError(f"no signal named {name!r}; recorded: {', '.join(self.columns)}")
        kind, idx = key
        if kind == "q":
            return self.q[:, idx]
        if kind == "qd":
            return self.qd[:, idx]
        return self.signals[idx]

    def __contains__(self, name: str) -> bool:
        return name in ("time", "t") or self._resolve(name) is not None

    def _resolve(self, name: str):
        for cand in _aliases(name):
            if cand in self.coordinates:
                return "q", self.coordinates.index(cand)
            inner_name, speed = split_state(cand)
            if speed:
                for inner in _aliases(inner_name):
                    if inner in self.coordinates:
                        return "qd", self.coordinates.index(inner)
            if cand in self.signals:
                return "s", cand
        # q1 -> q[1] style aliases for array coordinates
        for c in self.coordinates:
            if _plain(c) == name:
                return "q", self.coordinates.index(c)
            if f"der({_plain(c)})" == name:
                return "qd", self.coordinates.index(c)
        for s in self.signals:
            if _plain(s) == name:
                return "s", s
        old = (self.metadata.get("aliases") or {}).get(name) if isinstance(self.metadata, dict) else None
        if old is not None and old != name:
            return self._resolve(old)      # a signal's name before a rename (constraints: lambda[c1])
        return None

    # -- output -----------------------------------------------------------------------
    def table(self) -> np.ndarray:
        """Every column (``columns``) as one (n_t, n_columns) array: what the CSV holds."""
        import numpy as np

        if not len(self.t):
            return np.zeros((0, len(self.columns)))
        cols = [self.t[:, None], self.q, self.qd] + [np.asarray(v, float).reshape(len(self.t), -1)
                                                     for v in self.signals.values()]
        return np.hstack(cols)

    def to_csv_text(self) -> str:
        """The CSV (header of ``columns``, one row per output time, full precision) as text."""
        return csv_text(self.columns, self.table().astype(float, copy=False).tolist())

    def to_csv(self, path, sidecar: bool = True, overwrite: bool = False) -> list[str]:
        """Write the CSV and, by default, its JSON sidecar (OUT.csv -> OUT.json), atomically.

        An existing file that mechdsl did not write is replaced only with ``overwrite=True``
        (a UsageError otherwise); earlier results of mechdsl are replaced.  The sidecar records
        the CSV's SHA-256 (``csv_sha256``), so a pair torn apart by a crash between the two
        renames is recognisable.  Returns the paths written."""
        text = self.to_csv_text()
        items = [(path, text)]
        if sidecar:
            from ..digest import sha256

            summary = self.to_json_text(csv_sha256=sha256(text.encode("utf-8")).hexdigest())
            items.append((sidecar_path(path), summary))
        return [str(p) for p in write_atomic_group(items, overwrite)]

    def column_units(self) -> dict[str, str]:
        """The unit of every column ('' when the model gives none): coordinates and outputs in the SI
        unit of their declaration (the values are SI: "deg" is reported as rad), their rates per
        second, energies in J, time in s."""
        from .units import signal_units

        units = signal_units(self)
        return {c: units.get(c, "") for c in self.columns}

    def summary(self) -> dict[str, Any]:
        """What the JSON sidecar holds: metadata (model, settings, method and why, versions,
        accuracy), stats, success, failure, columns, each column's unit and events."""
        return {
            "generator": "mechdsl",
            "metadata": self.metadata,
            "stats": self.stats,
            "success": self.success,
            "failure": None if self.failure is None else {"time": self.failure.time, "cause": self.failure.cause,
                                                          "detail": self.failure.detail},
            "columns": self.columns,
            "units": self.column_units(),
            "events": self.events,
        }

    def to_json_text(self, **extra) -> str:
        """``summary()`` (and ``extra`` fields) as JSON text, keys sorted: the sidecar's text."""
        import json

        return json.dumps(_jsonable({**self.summary(), **extra}), indent=2, sort_keys=True) + "\n"

    # -- seeing it (mechdsl.output.display) ------------------------------------------------------
    def plot(self, *signals, **kw):
        """A matplotlib Figure: coordinates (one axis per unit), energies, drift (mechdsl.output.plot)."""
        from .plot import result_figure

        return result_figure(self, *signals, **kw)

    def animate(self, model=None, **kw):
        """An Animation of the mechanism (mechdsl.animate); model defaults to the one simulated."""
        from .display import animate_result

        return animate_result(self, model, **kw)

    def view(self, model=None, **kw):
        """The interactive 3-D view of the motion (mechdsl.view.View: ``.save("x.html")``; inline in
        Jupyter); fps, speed, up, trails as for animate; model defaults to the one simulated."""
        from .display import view_result

        return view_result(self, model, **kw)

    def to_pandas(self):
        """A pandas DataFrame indexed by time, units in ``df.attrs["units"]`` (needs the 'table' extra)."""
        from .display import to_pandas

        return to_pandas(self)

    def to_xarray(self):
        """An xarray Dataset over time, each variable's unit in its attrs (needs the 'table' extra)."""
        from .display import to_xarray

        return to_xarray(self)


def sidecar_path(path) -> str:
    """OUT.csv -> OUT.json (any other name: NAME.json appended)."""
    path = str(path)
    return path[:-4] + ".json" if path.endswith(".csv") else path + ".json"


def _csv_name(c: str) -> str:
    return f'"{c}"' if "," in c or '"' in c else c


def csv_text(columns, rows) -> str:
    """The CSV of the ``columns`` and the ``rows`` (sequences of Python floats): full precision
    (``repr``), the one text of Result.to_csv and of a prepared warm run."""
    lines = [",".join(_csv_name(c) for c in columns)]
    lines += [",".join(map(float.__repr__, row)) for row in rows]
    return "\n".join(lines) + "\n"


def _plain(name: str) -> str:
    return re.sub(r"\[(\d+)\]", r"\1", name).replace(".", "_")


def _aliases(name: str):
    yield name
    if name.startswith("L_(") and "," in name:       # an angular momentum's name before issue 23
        yield name.replace(",", ":")
    m = re.fullmatch(r"([A-Za-z_]\w*)(\d+)", name)
    if m:
        yield f"{m.group(1)}[{m.group(2)}]"


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    np = sys.modules.get("numpy")      # (not imported: no numpy value can be here)
    if np is not None:
        if isinstance(x, np.ndarray):
            return _jsonable(x.tolist())
        if isinstance(x, (np.floating,)):
            return float(x)
        if isinstance(x, (np.integer,)):
            return int(x)
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


class SimulationFailed(RuntimeError):
    """Raised by ``Result.raise_for_failure()``: the run failed (``.result`` keeps what it computed
    up to the failure, ``.result.failure`` says when and why)."""

    def __init__(self, message: str, result: Result):
        super().__init__(message)
        self.result = result


INTERRUPTED = "the run was interrupted (Ctrl-C); results up to here are kept"


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run (every back end): a KeyboardInterrupt that carries the partial Result
    (``.result``: failure "interrupted", metadata["interrupted"] = True, the rows reached), so
    a caller may write what was computed before it stops."""

    def __init__(self, result: Result):
        super().__init__("interrupted")
        self.result = result


_VERSIONS: dict = {}


def versions() -> dict[str, str]:
    """The versions a result was computed with (``metadata["versions"]``, stamped once by the
    simulation layer's template on every Result); read once per process (scipy's version.py
    is executed to read it: 0.3 ms a run)."""
    if not _VERSIONS:
        import platform

        import casadi
        import numpy as np

        from .. import __version__

        _VERSIONS.update({"mechdsl": __version__, "casadi": casadi.__version__, "numpy": np.__version__,
                          "scipy": _scipy_version(), "python": platform.python_version()})
    return dict(_VERSIONS)


def _scipy_version() -> str:
    """scipy.__version__ without importing scipy (8 ms) when the run did not: its version.py
    is a file of plain assignments, read on its own."""
    mod = sys.modules.get("scipy")
    if mod is None:
        import importlib.util
        import os

        try:
            spec = importlib.util.find_spec("scipy")
            where = os.path.join(os.path.dirname(spec.origin), "version.py")
            vspec = importlib.util.spec_from_file_location("_mechdsl_scipy_version", where)
            vmod = importlib.util.module_from_spec(vspec)
            vspec.loader.exec_module(vmod)
            return str(vmod.version)
        except Exception:     # another layout: ask scipy itself
            pass
        import scipy as mod
    return str(mod.__version__)
