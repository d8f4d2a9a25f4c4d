"""What a scene computes and why (issue 17): Problem.plan and Problem.reactions, printed by
`mech check` for every scene and by `mech compile --emit problem`; and what a scene does not
use is not built (checked on the problem and on the functions the run built, not by timing)."""
from __future__ import annotations

import pytest

import mechdsl
from mechdsl.cli import main

from conftest import MODELS

FOUR_BAR = (MODELS / "four_bar.mech").read_text()
ANGLES_ONLY = FOUR_BAR + """
scene Angles "only the angles"
  model FourBar;
  stop_time = 0.2;
  points = 5;
  outputs = {crank_angle};
end Angles;
"""


def _recorded_columns(monkeypatch) -> list[str]:
    """The names of every column the run asks the one recorder (simulation/record.py) to build."""
    from mechdsl.simulation import record as R

    seen: list[str] = []
    real = R.record

    def spy(eom, columns, *a, **kw):
        seen.extend(columns)
        return real(eom, columns, *a, **kw)

    monkeypatch.setattr(R, "record", spy)
    return seen


def test_a_scene_that_records_no_reaction_builds_none(monkeypatch):
    seen = _recorded_columns(monkeypatch)
    m = mechdsl.loads(ANGLES_ONLY, scene="Angles")
    problem = m.problem()
    plan = dict(problem.plan)
    assert problem.reactions == ()
    assert plan["reactions"].startswith("not computed")
    assert "not generated: rocker_angle, F_close[1], F_close[2], F_close[3]" in plan["outputs"]
    r = m.simulate()
    assert r.success and "crank_angle" in r.signals
    assert not [k for k in r.signals if k.startswith("F_close") or k.startswith("lambda[")]
    built = [name for name in seen if name in m.eom.outputs or name.startswith("lambda[") or "F_close" in name]
    # neither the other outputs nor the reactions were generated (the error estimate's companion
    # run records the run's own columns again)
    assert sorted(set(built)) == ["crank_angle"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_scene_whose_output_uses_reactions_computes_them():
    m = mechdsl.loads(FOUR_BAR, scene="Swing")
    problem = m.problem(t_end=0.2, points=5)
    assert problem.reactions == ("F_close[1]", "F_close[2]", "F_close[3]")
    assert "outputs F_close[1], F_close[2], F_close[3] use them" in dict(problem.plan)["reactions"]
    r = m.simulate(t_end=0.2, points=5)
    # the closing hinge carries part of the weight: not zero (the multipliers were computed)
    assert max(abs(r.signals["F_close[2]"])) > 1e-2
    asked = mechdsl.loads(ANGLES_ONLY, scene="Angles").problem(reactions=True)
    assert "reactions = true" in dict(asked.plan)["reactions"] and asked.reactions


def test_plan_names_the_formulation_and_its_reason():
    assert dict(mechdsl.load(MODELS / "bouncing_ball.mech", scene="Bounce").problem().plan)["formulation"] \
        .startswith("hybrid (events back end): the model has contacts (floor)")
    kepler = dict(mechdsl.load(MODELS / "kepler.mech", scene="Orbits").problem().plan)
    assert kepler["formulation"].startswith("canonical") and "stormer-verlet" in kepler["formulation"]
    assert kepler["invariants"].startswith("energy (")
    pend = dict(mechdsl.load(MODELS / "pendulum.mech").problem(t_end=1.0).plan)
    assert pend["formulation"].startswith("ode") and pend["reactions"] == "none (no constraints)"


def test_check_prints_the_plan_of_every_scene(tmp_path, capsys):
    path = tmp_path / "fb.mech"
    path.write_text(ANGLES_ONLY)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    swing, angles = out.split("  scene Swing")[1].split("  scene Angles")
    assert "    reactions: computed" in swing and "    reactions: not computed" in angles
    assert "    formulation: dae, formulation projection" in angles
    assert "    invariants: energy" in angles


def test_check_plans_a_scene_without_stop_time(tmp_path, capsys):
    """A scene without stop_time (and a late start) still gets its plan: the end does not matter."""
    path = tmp_path / "late.mech"
    path.write_text((MODELS / "pendulum.mech").read_text().split("scene ")[0]
                    + "scene Late\n  model " + mechdsl.load(MODELS / "pendulum.mech").model.name
                    + ";\n  start_time = 5;\nend Late;\n")
    assert main(["check", str(path), "--scene", "Late"]) == 0
    assert "    formulation: ode in minimal coordinates" in capsys.readouterr().out
