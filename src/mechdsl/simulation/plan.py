"""What a run computes and why: the plan of a Problem (issue 17, "model no more than a scene needs").

``plan(eom, settings, kind, ...)`` returns ``(topic, text)`` pairs for four topics, each saying
what the run will compute and the reason, and what it leaves out:

  formulation  the problem kind and back end (contacts -> events, a fixed-step method ->
               canonical, constraints -> DAE with its formulation, else an ODE)
  outputs      the declared outputs recorded (all, or those the scene's `outputs` names) and
               the ones not generated
  reactions    whether the constraint multipliers are computed: only when a recorded output
               uses them, `outputs` names one, or `reactions = true` (dae/record.py decides; the
               same rule is read here, so the report cannot disagree with the run)
  invariants   the quantities whose drift the run reports (energy when the model conserves it,
               declared invariants), or why the energy is not one

``mech check`` prints the plan of every scene and ``mech compile --emit problem`` prints it
with the problem (docs/simulate.md, "What a scene computes").
"""
from __future__ import annotations

from .monitors import MAX_INTEGRAL_SEARCH
from .record_dae import depends_on, lam_symbol, reaction_sources, select_signals


def plan(eom, settings, kind: str, contacts: tuple[str, ...], outputs: tuple[str, ...],
         invariants: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    return (("formulation", _formulation(eom, settings, kind, contacts)),
            ("outputs", _outputs(eom, settings, outputs)),
            ("reactions", _reactions(eom, settings, kind)[1]),
            ("invariants", _invariants(eom, kind, invariants)))


def reaction_signals(eom, settings, kind: str) -> tuple[str, ...]:
    """The reaction and multiplier signals the run will compute (empty: none are built)."""
    return _reactions(eom, settings, kind)[0]


def _formulation(eom, settings, kind, contacts) -> str:
    if kind == "hybrid":
        return f"hybrid (events back end): the model has contacts ({', '.join(contacts)}), located as events"
    if kind == "canonical":
        return f"canonical (fixed-step back end): method = {settings.method!r} integrates in canonical variables"
    if kind == "dae":
        f = settings.formulation
        how = f"{f} (asked for)" if f != "auto" else "projection (the default: `formulation` not set)"
        loops = getattr(getattr(eom, "model", None), "loops", ()) or ()
        why = f"{eom.m} constraint equations" + (f" ({len(loops)} closed loop{'s' if len(loops) != 1 else ''})" if loops else "")
        return f"dae, formulation {how}: {why}"
    return "ode in minimal coordinates: no constraints, no contacts"


def _outputs(eom, settings, outputs) -> str:
    declared = list(getattr(eom, "outputs", {}) or {})
    if settings.outputs is None:
        if not declared:
            return "none declared (coordinates, speeds and energies are always recorded)"
        return f"all {len(declared)} declared ({', '.join(declared)}): the scene names no `outputs`"
    kept = [o for o in declared if o in outputs]
    left = [o for o in declared if o not in outputs]
    text = (f"{', '.join(kept)} (named in `outputs`)" if kept else "no declared output (`outputs` names none)")
    return text + (f"; not generated: {', '.join(left)}" if left else "")


def _reactions(eom, settings, kind) -> tuple[tuple[str, ...], str]:
    if kind != "dae":
        why = {"hybrid": "contact forces come from the impact and contact laws",
               "canonical": "a fixed-step run computes no multipliers"}.get(kind, "no constraints")
        return (), f"none ({why})"

    chosen, need = select_signals(eom, settings.outputs, settings.reactions)
    lam = lam_symbol(eom)
    sources = reaction_sources(eom)
    named = tuple(k for k in chosen if k in sources and k not in eom.outputs)
    users = [k for k, v in chosen.items() if k in eom.outputs and depends_on(v, lam)]
    if not need:
        return (), "not computed: no recorded output uses the multipliers and reactions = false"
    reasons = []
    if settings.reactions:
        reasons.append("reactions = true")
    if users:
        reasons.append(f"output{'s' if len(users) > 1 else ''} {', '.join(users)} use{'' if len(users) > 1 else 's'} them")
    if named and not settings.reactions:
        reasons.append(f"`outputs` names {', '.join(named)}")
    what = tuple(users) + named
    return what, f"computed ({eom.m} multipliers at every output time): {'; '.join(reasons)}"


def _invariants(eom, kind, invariants) -> str:
    declared = [n for n in invariants if n != "energy"]
    parts = []
    if "energy" in invariants:
        parts.append("energy (no damping, no non-conservative forces, nothing depends on time)")
    else:
        parts.append(f"energy is not monitored ({_not_conserved(eom, kind)})")
    if declared:
        parts.append(f"declared: {', '.join(declared)}")
    if kind == "ode" and eom.n and not getattr(getattr(eom, "model", None), "contacts", None):
        parts.append("first integrals searched and recorded" if eom.n <= MAX_INTEGRAL_SEARCH else
                     f"first integrals not searched (more than {MAX_INTEGRAL_SEARCH} coordinates)")
    return "; ".join(parts)


def _not_conserved(eom, kind) -> str:
    import casadi as ca

    if kind == "hybrid":
        return "impacts change it"
    if not ca.SX(eom.D).is_zero():
        return "damping"
    if not ca.SX(eom.Q).is_zero():
        return "non-conservative forces"
    if ca.depends_on(ca.vertcat(ca.SX(eom.T), ca.SX(eom.V)), eom.t):
        return "T or V depends on time"
    return "a constraint moves with time"
