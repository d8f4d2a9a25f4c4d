"""The example models shipped with mechdsl (the repository's models/ folder).

    import mechdsl.examples
    mechdsl.examples.names()                    # ['andrews', 'bead_on_hoop', ...]
    mechdsl.examples.path("double_pendulum")    # Path to double_pendulum.mech
    mechdsl.load(mechdsl.examples.path("pendulum"), scene="Swing")
    mechdsl.examples.copy("ex")                 # copies every model into ./ex

One source of truth: the wheel carries models/*.mech inside this package (pyproject.toml,
``[tool.hatch.build.targets.wheel.force-include]``); an editable install, whose package folder
holds only this file, reads the checkout's models/ folder instead.  ``mech examples`` is the
command-line face of this module.
"""
from __future__ import annotations

from pathlib import Path

from ..diagnostics import UsageError, did_you_mean

SUFFIX = ".mech"


def folder() -> Path:
    """The folder holding the example ``.mech`` files: inside the installed package (a wheel),
    else the checkout's models/ folder (an editable install)."""
    here = Path(__file__).resolve().parent
    if any(here.glob("*" + SUFFIX)):
        return here
    checkout = here.parents[2] / "models"
    if any(checkout.glob("*" + SUFFIX)):
        return checkout
    from ..diagnostics import InternalError

    raise InternalError(f"the example models are missing (looked in {here} and {checkout}): a broken installation")


def names() -> list[str]:
    """The examples' names (file names without ``.mech``), sorted."""
    return sorted(p.stem for p in folder().glob("*" + SUFFIX))


def files() -> list[Path]:
    """Paths of every example file, sorted by name."""
    return [folder() / (n + SUFFIX) for n in names()]


def path(name: str) -> Path:
    """The path of one example: ``path("pendulum")`` (``"pendulum.mech"`` works too).  An unknown
    name is a UsageError that lists the examples (with a did-you-mean)."""
    stem = str(name)
    if stem.endswith(SUFFIX):
        stem = stem[: -len(SUFFIX)]
    known = names()
    if stem not in known:
        hint = did_you_mean(stem, known)
        raise UsageError(f"no example named {name!r}" + (f"; {hint}" if hint else "")
                         + f" (examples: {', '.join(known)})")
    return folder() / (stem + SUFFIX)


def description(name: str) -> str:
    """The one-line description of an example: the description string of the model the file
    runs by default (its first scene's model, else its last model; as ``mech simulate FILE``)."""
    from ..frontend.ast import ModelDef, SceneDef, SceneModel
    from ..frontend.parser import parse_file

    tree = parse_file(path(name))
    models = {m.name: m for m in tree.items if isinstance(m, ModelDef)}
    target = None
    for scene in (s for s in tree.items if isinstance(s, SceneDef)):
        target = next((i.name for i in scene.items if isinstance(i, SceneModel)), None)
        break
    chosen = models.get(target) if target else (list(models.values())[-1] if models else None)
    return (chosen.doc or "").strip() if chosen is not None else ""


def catalog() -> list[tuple[str, str]]:
    """(name, one-line description) of every example, sorted by name."""
    return [(n, description(n)) for n in names()]


def copy(destination, force: bool = False, only=None) -> list[Path]:
    """Copy the examples (or the names in ``only``) into the folder ``destination`` (made if
    missing).  An existing file there is never replaced unless ``force``: then nothing is copied
    and a UsageError names the files in the way.  Returns the paths written."""
    dest = Path(destination)
    if dest.exists() and not dest.is_dir():
        raise UsageError(f"{dest} exists and is not a folder")
    chosen = [path(n) for n in only] if only else files()
    clash = [dest / p.name for p in chosen if (dest / p.name).exists()]
    if clash and not force:
        listed = ", ".join(str(c) for c in clash[:5]) + (f" and {len(clash) - 5} more" if len(clash) > 5 else "")
        raise UsageError(f"{listed} already exist{'s' if len(clash) == 1 else ''}; give --force to replace "
                         f"{'it' if len(clash) == 1 else 'them'}")
    if not dest.exists() and not dest.parent.is_dir():
        raise UsageError(f"cannot create {dest}: the folder {dest.parent} does not exist (create it first)")
    dest.mkdir(exist_ok=True)
    return [_write(dest / p.name, p.read_bytes()) for p in chosen]


def _write(target: Path, data: bytes) -> Path:
    """Atomically (a temporary file beside it, then a rename), with the umask's mode.
    (mechdsl.output.fileio refuses to replace any .mech file; here --force asked for it.)"""
    import os

    from ..output.fileio import _new_temp

    fd, tmp = _new_temp(target)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target


__all__ = ["folder", "names", "files", "path", "description", "catalog", "copy"]
