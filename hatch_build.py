"""Build hook: the stepping loop's runtime library (crk.c + vm.c) compiled when mechdsl is installed.

A first `mech simulate` on a new machine then loads it instead of running gcc for it (issue 24,
item 8; src/mechdsl/simulation/backends/runtime_lib.py says how it is found and checked).

- a wheel (``pip install .``, ``pip wheel .``): built in a temporary folder and put into the wheel
  as ``mechdsl/simulation/backends/_runtime/crk-<key>.so``; the wheel is then platform-specific;
- an editable install (``pip install -e .``): built into the source tree,
  ``src/mechdsl/simulation/backends/_runtime/`` (gitignored), where the editable install and a
  checkout run with ``PYTHONPATH=src`` (benchmarks/) find it.

No C compiler, or a failed compile, does not fail the install: a warning, and the library is
built into the cache folder on the first run, as without this hook.  Only the standard library
and hatchling: mechdsl's dependencies are not in the build environment (runtime_lib.py and
eom/compiler.py are loaded by their paths).
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import tempfile

from hatchling.builders.hooks.plugin.interface import BuildHookInterface


def _load(name: str, path: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class RuntimeLibraryHook(BuildHookInterface):
    PLUGIN_NAME = "custom"

    def initialize(self, version, build_data):
        if self.target_name != "wheel":
            return
        src = os.path.join(self.root, "src", "mechdsl")
        compiler = _load("_mechdsl_build_compiler", os.path.join(src, "eom", "compiler.py"))
        rt = _load("_mechdsl_build_runtime_lib", os.path.join(src, "simulation", "backends", "runtime_lib.py"))
        cc = compiler.find_compiler()
        if cc is None:
            self.app.display_warning("mechdsl: no C compiler ($CC, gcc, cc, clang): the stepping loop's runtime "
                                     "library is built on the first run instead")
            return
        editable = version == "editable"
        self._tmp = None if editable else tempfile.mkdtemp(prefix="mechdsl-wheel-runtime-")
        try:
            path, why = rt.build(rt.PACKAGED if editable else self._tmp, compiler.build_shared, cc)
        except Exception as e:  # noqa: BLE001 - never fail the install for it
            path, why = None, f"{type(e).__name__}: {e}"
        if path is None:
            self.app.display_warning(f"mechdsl: the stepping loop's runtime library did not compile ({why}); "
                                     "it is built on the first run instead")
            return
        self.app.display_info(f"mechdsl: built the stepping loop's runtime library {os.path.basename(path)}")
        if not editable:
            build_data["force_include"][path] = f"mechdsl/simulation/backends/_runtime/{os.path.basename(path)}"
        build_data["pure_python"] = False       # a compiled library inside: a platform wheel
        build_data["infer_tag"] = True

    def finalize(self, version, build_data, artifact_path):
        tmp = getattr(self, "_tmp", None)
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
