"""A Pygments lexer for ``.mech`` files, registered as the plug-in ``mech`` (entry point group
``pygments.lexers``), so ``pygmentize -l mech``, Jupyter and Sphinx highlight models.

Pygments imports this module itself; mechdsl never does, so Pygments is no dependency of the
package.  The word lists are written out here (the lexer must import nothing heavy); a test
checks them against the grammar (grammar/mech.lark) and the semantic tables, so they cannot drift.
"""
from __future__ import annotations

from pygments.lexer import RegexLexer, bygroups, words
from pygments.token import Comment, Keyword, Name, Number, Operator, Punctuation, String, Whitespace

KEYWORDS = ("model", "scene", "end", "extends", "equation", "for", "in", "loop", "if", "then", "elseif",
            "else", "connect", "each", "and", "or", "not")
DECLARATIONS = ("parameter", "coordinate", "output", "input", "constant")
ENERGY_WORDS = ("kinetic", "potential", "dissipation", "force")
CONSTANTS = ("true", "false")
TYPES = ("Real", "Integer", "Boolean", "String")
COMPONENTS = ("Body", "Box", "Contact", "Cylinder", "Cylindrical", "Damper", "Disk", "Fixation", "Fixed", "Force",
              "Friction",
              "Frame", "Free", "GeneralizedForce", "Gravitation", "Gravity", "Planar", "Point", "PointMass",
              "Potential", "Prismatic", "Revolute", "RigidLink", "Rod", "Shape", "Sphere", "Spherical", "Spring",
              "SpringDamper",
              "Torque")
FUNCTIONS = ("abs", "acos", "asin", "atan", "atan2", "ceil", "cos", "cosh", "cross", "der", "diagonal",
             "dissipation_function", "dot", "energy", "exp", "fill", "floor", "identity", "kinetic_energy", "log",
             "log10", "max", "min", "norm", "normalize", "ones", "position", "potential_energy",
             "reaction_force", "reaction_torque", "rotation", "rpy", "axis_angle", "sign", "sin", "sinh", "size",
             "skew", "sqrt", "sum", "tan", "tanh", "transpose", "velocity", "zeros")
BUILTIN_NAMES = ("pi", "time", "world")


class MechLexer(RegexLexer):
    """mechdsl models: declarations, components, equations and scenes."""

    name = "mechdsl"
    aliases = ["mech", "mechdsl"]
    filenames = ["*.mech"]
    mimetypes = ["text/x-mechdsl"]
    url = "https://pypi.org/project/mechdsl/"

    tokens = {
        "root": [
            (r"[ \t\f\r\n]+", Whitespace),
            (r"//[^\n]*", Comment.Single),
            (r"/\*", Comment.Multiline, "comment"),
            (r'"', String.Double, "string"),
            (r"(model|scene)(\s+)([A-Za-z_]\w*)", bygroups(Keyword, Whitespace, Name.Class)),
            (r"(end)(\s+)([A-Za-z_]\w*)", bygroups(Keyword, Whitespace, Name.Class)),
            (words(DECLARATIONS, suffix=r"\b"), Keyword.Declaration),
            (r"(kinetic|potential|dissipation|force)(\s*)(=)(?!=)", bygroups(Keyword.Pseudo, Whitespace, Operator)),
            (words(KEYWORDS, suffix=r"\b"), Keyword),
            (words(CONSTANTS, suffix=r"\b"), Keyword.Constant),
            (words(TYPES, suffix=r"\b"), Keyword.Type),
            (words(COMPONENTS, suffix=r"\b"), Name.Builtin),
            (words(FUNCTIONS, suffix=r"\b(?=\s*\()"), Name.Function),
            (words(BUILTIN_NAMES, suffix=r"\b"), Name.Builtin.Pseudo),
            (r"[A-Za-z_]\w*", Name),
            (r"(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?", Number),
            (r"<=|>=|==|<>|[<>=+\-*/^]", Operator),
            (r"[()\[\]{},;.:]", Punctuation),
        ],
        "comment": [
            (r"[^*]+", Comment.Multiline),
            (r"\*/", Comment.Multiline, "#pop"),
            (r"\*", Comment.Multiline),
        ],
        "string": [
            (r'[^"\\\n]+', String.Double),
            (r"\\.", String.Escape),
            (r'"', String.Double, "#pop"),
        ],
    }


__all__ = ["MechLexer"]
