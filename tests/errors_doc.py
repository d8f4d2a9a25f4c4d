"""Writes docs/errors.md: every front-end error code with its meaning, a bad example, the real
output of `mech check` on it, and the fix.  The examples are files of the broken-input corpus
(tests/corpus/, without their `// expect:` lines) or short texts given here; the output is
produced by running the CLI, so the page cannot drift from the code:
tests/test_corpus.py fails when the committed page differs from what this script generates.

    PYTHONPATH=src python tests/errors_doc.py            # rewrite docs/errors.md
    PYTHONPATH=src python tests/errors_doc.py --check    # exit 1 if it is stale
"""
from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

# the page lives in the source checkout (MECHDSL_CHECKOUT when the tests run from a copy elsewhere)
ROOT = Path(os.environ.get("MECHDSL_CHECKOUT") or Path(__file__).resolve().parents[1])
CORPUS = Path(__file__).resolve().parent / "corpus"
DOCS = ROOT / "docs" / "errors.md"
FILE = "example.mech"
URDF = "example.urdf"
DATA = "data.csv"
FIT = f"mech fit {FILE} --data {DATA} --fit L"


@dataclass(frozen=True)
class Entry:
    code: str
    title: str
    meaning: str
    fix: str
    corpus: str | None = None       # a corpus file whose text (without `// expect:` lines) is the example
    source: str | None = None       # or the example text itself
    shown: str | None = None        # what the page shows instead of the example (binary/huge inputs)
    command: str | None = None      # the command line shown (default: mech check example.mech)
    urdf: str | None = None         # a file of tests/corpus/urdf/: the example of a `mech import` error
    data: str | None = None         # a file of tests/corpus/fit/: the example of a `mech fit` data error


PENDULUM = """model Pendulum
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1;
  coordinate Real theta(start = 1, unit = "rad");
equation
  kinetic = 1/2*m*L^2*der(theta)^2;
end Pendulum;
"""

SECTIONS = [
    ("Files (E0xx)", "Problems reading the file itself."),
    ("Syntax (E1xx)", "The text does not follow the grammar (grammar/mech.lark). Syntax errors stop at the "
                      "first one."),
    ("Names and declarations (E2xx)", "Declarations, references and components. Reported together, sorted by "
                                      "position."),
    ("Shapes and values (E3xx)", "Scalars, vectors and matrices; values that cannot be computed; what may depend "
                                 "on what."),
    ("Units (E4xx)", "Dimensional analysis of every expression. Quantities declared without a unit are never "
                     "an error; literal numbers are pure numbers."),
    ("Topology (E5xx)", "The kinematic graph: every body must hang from the world through joints."),
    ("Scenes (E6xx)", "Scene settings and the model a scene names."),
    ("URDF import (E020-E028)", "`mech import ROBOT.urdf -o ROBOT.mech` (docs/import.md) locates every problem "
                                "at the URDF element it is about. Besides these codes it reports the file "
                                "errors E001-E006 and, for the inertia data of a link (after fixed links are "
                                "merged into it), E508 and E509 at the link's `<inertial>`. Its warnings: W021 "
                                "a mesh that cannot be read (an unknown format, a damaged file), or one not found "
                                "with `--skip-missing-meshes` (that visual is not drawn), W025 a joint that "
                                "closes a loop (left out: URDF describes trees), W026 a joint axis with components "
                                "below 1e-8 of its largest (an exporter's rounding such as `0 -1 6.12323e-17`, "
                                "set to 0: a .mech file refuses such an axis with E513), W029 a mimic that names no "
                                "movable joint (left out: the joint moves on its own), W509 an inertia that breaks "
                                "the triangle inequality by rounding."),
    ("Data for a fit (E771-E773)", "`mech fit MODEL --data DATA.csv --fit NAME` and `Model.fit` ([fitting.md](fitting.md)) "
                                   "check the measured data before any run and locate every problem in the data file "
                                   "(its line and column; a table in memory names the column and sample). The "
                                   "examples fit the pendulum above (`example.mech`) to `data.csv`; the corpus "
                                   "is tests/corpus/fit/."),
]

ENTRIES = [
    # ------------------------------------------------------------------ E0xx
    Entry("E001", "file not found", "The path given to `mech` does not exist (or cannot be read).",
          "Check the path; models are `.mech` files.", command="mech check missing.mech"),
    Entry("E002", "not a text file", "The file is not valid UTF-8, or it contains a NUL byte (a binary file).",
          "Save the file as UTF-8 text.", corpus="E002_non_utf8.mech",
          shown="model A\n  parameter Real x = 1; // caf\\xe9   <- the byte 0xe9 (Latin-1 for é)\nend A;\n"),
    Entry("E003", "a directory", "The path names a directory, not a file.",
          "Pass the files inside it: `mech check models/*.mech`.", command="mech check models"),
    Entry("E004", "no model", "The file is empty, or holds only comments and blank lines.",
          "Write at least one `model Name ... end Name;`.", corpus="E004_only_comments.mech"),
    Entry("E005", "file too large", "The file is larger than the `file_bytes` limit (1 MB; checked before "
                                    "reading): not a hand-written model.",
          "Split it, or generate smaller models; `--limit file_bytes=N` raises the limit.",
          command="mech check big.mech"),
    Entry("E006", "not a regular file", "The path names a FIFO, a device (such as `/dev/zero`) or a socket: "
                                        "reading it could block or never end, so it is refused before opening.",
          "Save the model to an ordinary file and check that.", command="mech check /dev/zero"),
    # ------------------------------------------------------------------ E1xx
    Entry("E101", "unexpected character", "A character that cannot start any token, such as `$`, `'` or `×`.",
          "Remove it. Strings use double quotes; multiplication is `*`.", corpus="E101_dollar.mech"),
    Entry("E102", "unexpected token", "A token where the grammar does not allow it; the hint lists what would "
                                      "fit. A lone `=` in a condition is the classic case.",
          "Follow the hint; compare with `==`.", corpus="E102_assign_in_condition.mech"),
    Entry("E103", "unexpected end of file", "The file ends inside a model, scene or expression.",
          "Close the model with `end Name;` (the hint names the one left open).",
          corpus="E103_model_not_closed.mech"),
    Entry("E104", "nested too deeply", "Brackets nested more than 200 deep, or an expression tree deeper than "
                                       "600 levels.",
          "Split the expression with intermediate `Real` variables, or use `sum()` over an array.",
          source="model A\n  parameter Real x = " + "(" * 201 + "1" + ")" * 201 + ";\nend A;\n",
          shown="model A\n  parameter Real x = ((((...(1)...))));   // 201 nested parentheses\nend A;\n"),
    Entry("E105", "reserved word as a name", "A keyword (`end`, `loop`, `model`, `force`, ...) used as a name.",
          "Rename it, e.g. `end_`; the list of reserved words is in docs/language.md.",
          corpus="E105_keyword_as_name.mech"),
    Entry("E106", "malformed number", "A number glued to another number or a name (`1.2.3`, `2L`), or a stray "
                                      "`.`.",
          "Write numbers as `1`, `0.5`, `2e-3`; multiply explicitly: `2*L`.",
          corpus="E106_implicit_multiplication.mech"),
    Entry("E107", "missing ';'", "A statement is not ended by `;`. The caret points just after the statement.",
          "Add the `;`.", corpus="E107_missing_semicolon.mech"),
    Entry("E108", "unterminated string", "A string with no closing `\"` on its line.",
          "Close the string on the same line; write a line break as `\\n`.", corpus="E108_unterminated_string.mech"),
    Entry("E109", "unterminated comment", "A `/*` comment with no `*/`.",
          "Close the comment with `*/`.", corpus="E109_unterminated_comment.mech"),
    Entry("E110", "mismatched end", "`end Name;` does not repeat the name of its model or scene.",
          "Write the same name after `end`.", corpus="E110_mismatched_end.mech"),
    # ------------------------------------------------------------------ E2xx
    Entry("E201", "undefined name", "A name that is not declared in the model and is not built in (`time`, "
                                    "`world`, `pi`), or a scene output the model does not have.",
          "Fix the spelling (the hint suggests a close name) or declare it.",
          corpus="E201_undefined_in_binding.mech"),
    Entry("E202", "declared twice", "Two declarations, models, scenes, modifiers or settings with one name.",
          "Rename or remove one of them.", corpus="E202_duplicate_declaration.mech"),
    Entry("E203", "unknown type", "A declaration whose type is neither `Real`/`Integer`/`Boolean` nor a "
                                  "built-in component nor a model of the file.",
          "Fix the spelling (the hint suggests the component or model).",
          corpus="E203_unknown_type_typo.mech"),
    Entry("E204", "unknown modifier", "A modifier that the component or declaration does not have: a field of "
                                      "a component, an attribute such as `unit` or `start`, or a name modified "
                                      "by a scene or an `extends` clause that the model does not declare.",
          "Fix the spelling; the hint lists the allowed names.", corpus="E204_unknown_modifier_typo.mech"),
    Entry("E206", "unknown model", "`extends` or a scene names a model that is not in the file.",
          "Fix the name, or put the model in the same file.", corpus="E206_unknown_extends.mech"),
    Entry("E207", "cyclic extends", "A model extends itself, directly or through other models.",
          "Remove one `extends` of the cycle.", corpus="E207_cyclic_extends.mech"),
    Entry("E208", "cyclic definition", "Declarations defined in terms of each other (`a = b + 1; b = a;`), "
                                       "also through component fields and joint variables.",
          "Break the cycle: give one of them a value of its own.", corpus="E208_cyclic_parameters.mech"),
    Entry("E209", "wrong kind of component", "A point, body or joint is expected and something else is given "
                                             "(a number, a joint, a rod in `connect`).",
          "Name a body, a point on a body (`rod.a`) or `world`; connect joints, springs and dampers.",
          corpus="E209_number_as_point.mech"),
    Entry("E210", "required field missing", "A component lacks a field with no default (a `Rod` without `m`, "
                                            "a joint without `child`).",
          "Add the field to its modifiers (or set joint ends with `connect`).",
          corpus="E210_missing_required_field.mech"),
    Entry("E211", "field set twice", "A field given both as a modifier and by `connect(...)`, or alternatives "
                                     "given together (`I` and `I_11`, `R` and `angle`).",
          "Keep one of them.", corpus="E211_field_set_twice.mech"),
    Entry("E212", "no value", "A parameter without a value, or an output or variable without a definition.",
          "Give it one where it is declared: `parameter Real m = 1;`.",
          corpus="E212_parameter_without_value.mech"),
    Entry("E213", "unknown function", "A call of a function that is not built in.",
          "Fix the spelling; docs/language.md lists the functions.", corpus="E213_unknown_function.mech"),
    Entry("E214", "value not allowed", "A component or coordinate given a value with `=`.",
          "Components take modifiers (`Rod r(m = 1, L = 2)`); coordinates take `start`.",
          corpus="E214_component_with_value.mech"),
    Entry("E215", "prefix not allowed", "A prefix that does not fit the type: an Integer coordinate, a "
                                        "`parameter` component.",
          "Coordinates and inputs are `Real`; components take no prefix.", corpus="E215_integer_coordinate.mech"),
    Entry("E216", "built-in name declared", "A declaration named `time` or `world`.",
          "Choose another name.", corpus="E216_declares_time.mech"),
    Entry("E217", "invalid option", "A string field outside its allowed choices.",
          "Use one of the choices in the hint.", corpus="E217_bad_choice.mech"),
    Entry("E218", "not a coordinate", "`force(x) = ...` where `x` is not a coordinate.",
          "Name a `coordinate` or a joint variable such as `j1.phi`.", corpus="E218_force_on_parameter.mech"),
    Entry("E219", "unknown attribute", "`a.b` where `a` has no attribute `b` (points have `r v x y z`, bodies "
                                       "also `R w`, rods `a b`, joints their variables).",
          "Fix the spelling (the hint lists the attributes).", corpus="E219_unknown_attribute_of_body.mech"),
    Entry("E220", "vector start not applicable", "`omega(..)`, `r(..)` or `v(..)` of a Spherical or Free joint "
                                                 "without `start = {..}`, or on a joint whose variables are bound "
                                                 "to other coordinates or expressions (or that has no rotation "
                                                 "coordinates: a Free joint with a point-mass child has no omega).",
          "Write `omega(start = {wx, wy, wz})`, and set start values on the coordinates a bound joint uses.",
          corpus="E220_omega_without_start.mech"),
    Entry("E221", "omega in world axes on a moving parent", '`omega(start = .., frame = "world")` on a joint '
                                                            "whose parent is not the world: the world axes of "
                                                            "a relative angular velocity are not defined there.",
          'Give the angular velocity relative to the parent in the child body\'s axes: `frame = "body"`.',
          corpus="E221_omega_world_frame_on_moving_parent.mech"),
    Entry("E222", "omega at gimbal lock", "`omega(start = ..)` on an Euler-angle joint whose start orientation is "
                                          "at (within 1e-8 of) the gimbal lock of its sequence: the angle rates "
                                          "of an angular velocity are not unique or do not exist there.",
          'Start away from the lock, or use `parametrization = "quaternion"`.',
          corpus="E222_omega_at_gimbal_lock.mech"),
    Entry("E230", "input default not constant", "An `input`'s default value (`input Real F = ...`) that is "
                                                "not a constant number.",
          "Give a number (`= 0` when omitted); drive the input at run time (docs/control.md).",
          corpus="E230_input_default_not_constant.mech"),
    Entry("E231", "parameter depends on input", "A parameter computed from an `input`: inputs change during "
                                               "a run, parameters are constant.",
          "Use the input directly in the forces or equations.", corpus="E231_parameter_depends_on_input.mech"),
    Entry("E241", "friction regularization not positive", "A `Friction` whose regularization speed `v_eps` "
                                                          "is zero or negative (the law is -F tanh(v/v_eps)).",
          "Give v_eps > 0 (default 1e-3); smaller is closer to dry friction and stiffer.",
          corpus="E241_friction_nonpositive_v_eps.mech"),
    Entry("E232", "no such constraint", "`constraint_force(c, body)` / `constraint_torque(c, body)` names "
                                        "neither a constraint equation (by its description) nor a loop-closing "
                                        "joint.",
          "Name the constraint as `lambda[...]` does (its description, `c1`, ... without one) or the joint that "
          "closes the loop.", corpus="E232_constraint_force_unknown_constraint.mech"),
    Entry("E233", "no force at a point", "`constraint_force(c, body)` for a constraint that exerts no force on "
                                         "that body at a point: an equation written in coordinates (its "
                                         "multiplier is a generalized force), one that names no point of that "
                                         "body, or a joint of the tree (not closing a loop).",
          "Read the multiplier `lambda[c]` (docs/constraints.md), write the constraint in points, name a body "
          "it acts on, or use `reaction_force(j)` for a tree joint.",
          corpus="E233_constraint_force_in_coordinates.mech"),
    # ------------------------------------------------------------------ E3xx
    Entry("E301", "shape mismatch", "Scalars, vectors and matrices combined in a way their sizes do not allow, "
                                    "or a value whose shape differs from its declaration.",
          "Make the sizes agree (declared `[n]`, `{x, y, z}` for 3-vectors).",
          corpus="E301_vector_size_mismatch.mech"),
    Entry("E302", "not a number", "Arithmetic on a string or a component reference.",
          "Use numbers; for a point's position use its `.r`.", corpus="E302_string_arithmetic.mech"),
    Entry("E303", "value out of range", "An index outside the array, a division by zero, a function outside "
                                        "its domain, a complex power, a number or array that is too large.",
          "Fix the index or the formula (indices start at 1).", corpus="E303_index_out_of_range.mech"),
    Entry("E304", "wrong number of arguments", "A built-in function called with the wrong number of arguments.",
          "Follow the hint; docs/language.md lists the signatures.", corpus="E304_wrong_argument_count.mech"),
    Entry("E305", "second derivative", "`der()` of an expression that already contains speeds: accelerations "
                                       "are not available in models.",
          "Use `der()` on coordinates and functions of coordinates and time only.",
          corpus="E305_second_derivative.mech"),
    Entry("E306", "depends on the state", "A parameter, start value or moving frame that depends on coordinates "
                                          "(or a parameter or start value on time).",
          "Parameters are constants: use an `output` or a `Real` variable for quantities that change.",
          corpus="E306_parameter_depends_on_coordinate.mech"),
    Entry("E307", "not an Integer", "An array size, index or range bound that is not an Integer constant "
                                    "(e.g. a Real parameter), or an Integer parameter with a fractional value.",
          "Declare sizes as `parameter Integer N = ...`.", corpus="E307_real_array_size.mech"),
    Entry("E308", "speeds where positions are required", "A constraint equation, potential energy or joint "
                                                         "motion that contains `der(...)`.",
          "Constraints are holonomic (positions and time only); velocity-dependent forces go into `force(q) = "
          "...`, a `Force` or the dissipation function.", corpus="E308_constraint_with_der.mech"),
    Entry("E309", "equation without a coordinate", "An equation that involves no coordinate: equations are "
                                                   "constraints, not definitions.",
          "Define quantities where they are declared: `Real x = ...;`.",
          corpus="E309_equation_without_coordinate.mech"),
    Entry("E310", "zero vector", "An axis or direction that is the zero vector.",
          "Give a direction, e.g. `{0, 0, 1}`.", corpus="E310_zero_axis.mech"),
    Entry("E311", "planar normal not constant", "The normal of a `Planar` joint depends on coordinates or time.",
          "Write the normal with numbers or parameters.", corpus="E311_planar_normal_not_constant.mech"),
    Entry("E312", "bad Euler sequence", "A `sequence` that is not three axes with no two neighbours equal.",
          "Use e.g. `\"zyx\"` (Cardan) or `\"zxz\"` (Euler).", corpus="E312_bad_euler_sequence.mech"),
    Entry("E313", "outside min/max", "A parameter value below its `min` or above its `max` attribute.",
          "Change the value (or the bound).", corpus="E313_parameter_below_min.mech"),
    Entry("E314", "name too long", "An identifier or a unit string longer than the `name_length` limit (256 "
                                   "characters): such names come from generators gone wrong, make unreadable "
                                   "output, and a huge unit string takes pint minutes to parse.",
          "Use a shorter name (or `--limit name_length=N`).", corpus="E314_name_too_long.mech"),
    Entry("E315", "Integer parameter too large", "An Integer parameter beyond the `integers` limit (1,000,000 in "
                                                 "magnitude). Integer parameters are structural: they size arrays "
                                                 "and loops.",
          "Use a smaller value (or `--limit integers=N`).", corpus="E315_integer_parameter_too_large.mech"),
    Entry("E316", "model too large", "The model has more generalized coordinates (500), output scalars "
                                     "(10,000), component instances (10,000) or scalars in all (20,000) than "
                                     "the front end accepts: every one is derived and compiled symbolically, "
                                     "and far larger models would run for hours or exhaust memory.",
          "Make the model smaller, or raise the budget the message names with `--limit NAME=N` (see "
          "docs/language.md, Limits).", corpus="E316_too_many_coordinates.mech"),
    # ------------------------------------------------------------------ E4xx
    Entry("E317", "too many models", "The file holds more models and scenes than the `models` limit (500): "
                                     "`mech check` analyzes and derives each of them.",
          "Split the file (or `--limit models=N`).", corpus="E317_too_many_models.mech",
          shown="model M1\nend M1;\n...\nmodel M501\nend M501;\n"),
    Entry("E318", "not a rotation", "An orientation matrix `R` (of a point, joint or frame) that is not a "
                                    "rotation: not orthonormal, or a reflection (determinant -1).",
          "Build orientations with `rpy(r, p, y)`, `axis_angle(axis, angle)` or `rotation(axis, angle)`.",
          corpus="E318_orientation_not_rotation.mech"),
    Entry("E401", "incompatible units", "Two quantities with different units added, subtracted, compared or "
                                        "given as the branches of an `if`.",
          "Check the formula and the parameters' units.", corpus="E401_kg_plus_m.mech"),
    Entry("E402", "wrong unit", "A quantity whose unit differs from the one required: a component field "
                                "(spring constant in N/m), an energy (J), a generalized force, a declared unit.",
          "Check the formula and the parameters' units (the message shows both, in SI base units).",
          corpus="E402_spring_constant_unit.mech"),
    Entry("E403", "not dimensionless", "The argument of `sin`, `exp`, ..., or an exponent, has a unit.",
          "Divide by a reference quantity: `sin(x/L)`, `exp(-t/tau)`.", corpus="E403_sin_of_length.mech"),
    Entry("E404", "bad unit string", "A `unit` that is not a string or not a known unit.",
          "Write units like `\"kg\"`, `\"m/s2\"`, `\"N.m\"`, `\"rad\"` (Modelica style; pint reads the rest).",
          corpus="E404_unknown_unit.mech"),
    # ------------------------------------------------------------------ E5xx
    Entry("E501", "body not connected", "A body that no chain of joints connects to the world.",
          "Attach it with a joint, or make it free: `Free f(child = body);`.",
          corpus="E501_body_not_connected.mech"),
    Entry("E503", "connected to itself", "A joint (or a spring or damper) whose two ends lie on the same body.",
          "A joint's parent and child must lie on different bodies.", corpus="E503_joint_to_itself.mech"),
    Entry("E504", "world as a child", "A joint whose child is the world.",
          "Swap parent and child: the parent is the side nearer the world.", corpus="E504_world_as_child.mech"),
    Entry("E505", "reversed joint", "A joint from a body that is not connected to the world to one that is.",
          "Swap parent and child.", corpus="E505_reversed_joint.mech"),
    Entry("E506", "no coordinates", "A model with no degrees of freedom: no `coordinate` and no joint with a "
                                    "free variable.",
          "Declare `coordinate Real q(start = ...);` or add a joint.", corpus="E506_no_coordinates.mech"),
    Entry("E507", "loop joint bound", "The joint that closes a kinematic loop has a variable bound to a "
                                      "coordinate or an expression; the loop itself fixes that variable.",
          "Leave the loop-closing joint's variables unset, or close the loop at another joint.",
          corpus="E507_loop_joint_bound.mech"),
    Entry("E508", "negative mass", "A body whose mass evaluates to a negative number with the parameter values "
                                   "in force (also after `--set` or `with_params`). The equations of motion "
                                   "would run on a negative kinetic energy without failing.",
          "Fix the sign of `m` or of the parameters it uses.", corpus="E508_negative_mass.mech"),
    Entry("E509", "impossible inertia tensor", "An inertia tensor no rigid body can have: not symmetric, not "
                                               "positive semidefinite (a negative principal moment), or "
                                               "principal moments that break the triangle inequality "
                                               "I1 + I2 >= I3 by more than rounding (1e-6 of I3; less is the "
                                               "warning W509). A body that turns about one axis of its own "
                                               "only (a planar body on a hinge) is not judged by the triangle "
                                               "inequality: only its moment about that axis enters.",
          "Check the values and signs; each principal moment is at most the sum of the other two. For measured "
          "data you stand by, add `measured_inertia = true` to the `Body` (the tensor must still be positive "
          "semidefinite).", corpus="E509_inertia_triangle_inequality.mech"),
    Entry("E510", "value not finite", "A component value (a mass, length, inertia, spring coefficient, contact "
                                      "radius, axis) that evaluates to inf or nan with the parameter values in "
                                      "force (also after `--set` or `with_params`): a product of huge values that "
                                      "overflows, or a division by zero.",
          "Check the parameters the value uses; keep the numbers moderate (choose units).",
          corpus="E510_mass_not_finite.mech"),
    Entry("E511", "negative length", "A length, radius or size of a body (Rod, Disk, Cylinder, Sphere, Box), a "
                                     "contact radius or a rest length that is negative.",
          "Lengths are >= 0; to turn a body around, reverse its axis.", corpus="E511_negative_length.mech"),
    Entry("E512", "zero direction", "A joint axis, a body axis or a contact plane's normal that is the zero "
                                    "vector with the parameter values in force.",
          "Give a direction with a nonzero component (it is normalized for you).",
          corpus="E512_zero_normal.mech"),
    Entry("E513", "direction components far apart", "A joint axis, a body axis or a contact plane's normal whose "
                                                     "nonzero components are more than 1e8 times apart (such as "
                                                     "{1e32, 0, 1}): the small ones are below what double "
                                                     "precision resolves against the large ones.",
          "Set the tiny components to 0, or give the direction in numbers of comparable size.",
          corpus="E513_axis_components_far_apart.mech"),
    # ------------------------------------------------------------------ E6xx
    Entry("E601", "unknown scene setting", "A setting that scenes do not have.",
          "Fix the spelling; the hint suggests the setting.", corpus="E601_unknown_setting.mech"),
    Entry("E602", "unknown scene", "Through the Python API (`Program.scene(name)`), a scene that is not in the "
                                   "file. On the command line and in `mechdsl.load(scene=...)` the same mistake "
                                   "is a usage error (exit code 2).",
          "Fix the name.", command="python: analyze(parse_file(\"example.mech\")).scene(\"Swnig\")",
          source=PENDULUM + "\nscene Swing\n  model Pendulum;\nend Swing;\n"),
    Entry("E603", "scene without one model", "A scene that names no model, or more than one.",
          "Add exactly one `model Name;` line.", corpus="E603_scene_without_model.mech"),
    Entry("E020", "not XML", "The URDF file is not well-formed XML, or it declares a document type "
                             "(`<!DOCTYPE ...>`, where entities are defined: refused rather than expanded).",
          "Fix the XML at the place shown; remove a `<!DOCTYPE>`.", urdf="E020_not_xml.urdf"),
    Entry("E021", "not a URDF", "The document's root element is not `<robot>`, or the robot has no `<link>`.",
          "Import a URDF file (an SDF or a xacro file must be converted to URDF first).",
          urdf="E021_not_a_robot.urdf"),
    Entry("E022", "malformed element", "An element without a required attribute, a number that is not one (or "
                                       "not finite), an unknown joint type or geometry, an `<inertial>` without "
                                       "`<mass>` or `<inertia>`.",
          "Give the element what URDF requires; the message says what.", urdf="E022_inertial_without_inertia.urdf"),
    Entry("E023", "a joint that moves no mass", "A movable joint whose child link has no `<inertial>`, and no "
                                                "link beyond it has one: its coordinate would have no inertia.",
          "Give the link an `<inertial>`, or make the joint fixed.", urdf="E023_joint_moves_no_mass.urdf"),
    Entry("E024", "missing link", "A joint's parent or child link does not exist.",
          "Name a `<link>` of the robot (names are case-sensitive).", urdf="E024_missing_parent.urdf"),
    Entry("E025", "not a tree", "The joints form a cycle (no link is the root), the robot has several roots, or "
                                "some links are not reached from the root.",
          "A URDF is one tree: exactly one link (the base) is no joint's child, and each other link hangs from "
          "one joint.", urdf="E025_cycle.urdf"),
    Entry("E026", "a name used twice", "Two links, or two joints, with the same name.",
          "Rename one of them.", urdf="E026_link_twice.urdf"),
    Entry("E027", "nothing moves", "The robot has no movable joint (a quadrotor's body alone, a fixed "
                                   "assembly): the model would have no coordinates.",
          "Import it with `--floating` to give its root link a Free joint.", urdf="E027_nothing_moves.urdf"),
    Entry("E028", "mesh file not found", "A `<mesh filename>` names a file that is not there, or a "
                                         "`package://` whose ROS package is not found; a package is named "
                                         "once, at its first mesh, with the number of its meshes.",
          "Give the package's folder with `--package-dir NAME=DIR` (`package_dirs=` in Python), or import with "
          "`--skip-missing-meshes` (`skip_missing_meshes=True`): those visuals are then not drawn (the warning "
          "W021), which the dynamics do not need.", urdf="E028_missing_mesh.urdf"),
    # ------------------------------------------------------------------ E77x: data for a fit
    Entry("E771", "column names no signal", "A measured column is not a recorded signal of the model (the "
                                            "signals: coordinates, their speeds `der(q)`, outputs, energies), a "
                                            "column appears twice, or there is no column besides the time.",
          "Name the column like the signal (the hint lists them), or leave it out of the file.",
          data="E771_unknown_column.csv"),
    Entry("E772", "bad times", "No time column (`time` or `t`, in seconds), no samples, times not increasing, or "
                               "a time outside the run (before the scene's start; after `--t-end` when given).",
          "Sort the samples by time, one per time, inside the run.", data="E772_not_increasing.csv"),
    Entry("E773", "not a finite number", "A value is not a number, is `nan` or infinite, or a line has fewer or "
                                         "more values than the header names.",
          "Give every sample a finite value; drop a sample that was not measured (its row) or the column.",
          data="E773_not_a_number.csv"),
    Entry("E604", "bad setting value", "A setting of the wrong kind (a string for a number, a fraction for "
                                       "`points`, a negative tolerance, an unknown name).",
          "Give a value of the kind the message names.", corpus="E604_stop_time_string.mech"),
]


def corpus_text(name: str) -> bytes:
    data = (CORPUS / name).read_bytes()
    if data.startswith(b"// expect:"):
        lines = data.decode("utf-8").splitlines(keepends=True)
        return "".join(l for l in lines if not l.startswith("// expect:")).encode("utf-8")
    return data


def run(entry: Entry) -> tuple[str, str]:
    """(text shown as the example, output of the command), produced in a temporary folder."""
    from mechdsl.frontend import limits
    from mechdsl.frontend import parser as P
    from mechdsl.cli import main
    from mechdsl.diagnostics import MechError
    from mechdsl.diagnostics import format_diagnostics

    data = corpus_text(entry.corpus) if entry.corpus else (entry.source or "").encode("utf-8")
    if entry.urdf:
        lines = (CORPUS / "urdf" / entry.urdf).read_text(encoding="utf-8").splitlines(keepends=True)
        data = "".join(l for l in lines if not l.startswith("<!-- expect:")).encode("utf-8")
    if entry.data:
        data = (CORPUS / "fit" / entry.data).read_bytes()
    old = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            args = ["check", FILE]
            if entry.urdf:
                Path(URDF).write_bytes(data)
                args = ["import", URDF, "-o", FILE]
            elif entry.data:
                Path(FILE).write_text(PENDULUM, encoding="utf-8")
                Path(DATA).write_bytes(data)
                args = FIT.split()[1:]
            else:
                Path(FILE).write_bytes(data)
            if entry.code == "E001":
                args = ["check", "missing.mech"]
            elif entry.code == "E003":
                os.mkdir("models")
                args = ["check", "models"]
            elif entry.code == "E006":
                args = ["check", "/dev/zero"]
            elif entry.code == "E005":
                with open("big.mech", "wb") as f:
                    f.truncate(limits.get("file_bytes") + 1)
                args = ["check", "big.mech"]
            err, out = io.StringIO(), io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
                if entry.code == "E602":
                    from mechdsl.semantic import analyze

                    try:
                        analyze(P.parse_file(FILE)).scene("Swnig")
                    except MechError as e:
                        print(format_diagnostics(e.diagnostics), file=sys.stderr)
                else:
                    rc = main(args)
                    assert rc == 1, f"{entry.code}: exit code {rc}\n{err.getvalue()}"
        finally:
            os.chdir(old)
    output = err.getvalue().rstrip("\n")
    assert f"error[{entry.code}]" in output.splitlines()[0], f"{entry.code} example prints:\n{output}"
    shown = entry.shown if entry.shown is not None else data.decode("utf-8")
    return shown, output


def generate() -> str:
    out = [
        "# Error codes",
        "",
        "<!-- Generated by tests/errors_doc.py from real `mech check` output; "
        "tests/test_corpus.py checks that it is current. -->",
        "",
        "Every problem in a model is reported as a coded diagnostic:",
        "",
        "```text",
        "file:line:col: error[CODE]: message",
        "    the source line",
        "    ^^^^ under the place",
        "  help: how to fix it",
        "```",
        "",
        "`mech check` reports every error it can find in a file together (syntax errors stop at the first), "
        "exits with code 1 when a model has errors and 2 for a wrong command line, and never shows a Python "
        "traceback. Each code below has a bad example, the exact output of `mech check` on it, and the fix. "
        "The broken-input corpus in tests/corpus/ holds at least one file for every code.",
        "",
        "Warnings (`warning[W...]`) do not stop a model: W501 says a coordinate appears in no kinetic energy "
        "and no joint; W509 says an inertia tensor breaks the triangle inequality by rounding (at most 1e-6 of "
        "I3, the amount is given) and is accepted; W401-W403 are the unit checks E401-E403 where a decimal literal (such as 9.81) may stand "
        "for a quantity with a unit.",
        "",
        "Codes of later phases (deriving and simulating: E6xx from E605 on, E7xx, E8xx) are described with "
        "those commands, except the data errors of `mech fit` (E771-E773), which are listed here.",
        "",
    ]
    by_section: dict[str, list[Entry]] = {}
    for e in ENTRIES:
        by_section.setdefault("u" if e.urdf else "f" if e.data else e.code[1], []).append(e)
    for (title, intro), digit in zip(SECTIONS, "0123456uf"):
        out += [f"## {title}", "", intro, ""]
        for e in by_section.get(digit, []):
            shown, output = run(e)
            cmd = e.command or (f"mech import {URDF} -o {FILE}" if e.urdf else FIT if e.data else f"mech check {FILE}")
            out += [f"### {e.code} {e.title}", "", e.meaning, ""]
            if e.code not in ("E001", "E003", "E005", "E006") or e.shown:
                out += ["```xml" if e.urdf else "```text" if e.data else "```mech", shown.rstrip("\n"), "```", ""]
            where = f" (tests/corpus/{e.corpus})" if e.corpus else (f" (tests/corpus/urdf/{e.urdf})" if e.urdf else
                                                                     f" (tests/corpus/fit/{e.data})" if e.data else "")
            out += [f"`{cmd}`{where}:", "", "```text", output, "```", "", f"**Fix:** {e.fix}", ""]
    return "\n".join(out).rstrip("\n") + "\n"


def main(argv: list[str]) -> int:
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    text = generate()
    if "--check" in argv:
        current = DOCS.read_text(encoding="utf-8") if DOCS.exists() else ""
        if current != text:
            print(f"{DOCS} is stale: run PYTHONPATH=src python tests/errors_doc.py", file=sys.stderr)
            return 1
        return 0
    tmp = DOCS.with_suffix(".md.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, DOCS)
    print(f"wrote {DOCS} ({len(ENTRIES)} codes)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
