"""Modal analysis of M x'' + C x' + K x = 0: frequencies, damping ratios, shapes.

Conservative case (C = 0, K symmetric): the symmetric generalized eigenproblem K phi = w^2 M phi
(scipy.linalg.eigh), real shapes.  Otherwise the eigenvalues of the first-order A; a complex
pair lambda = sigma +- i w_d is one mode, a real eigenvalue is one mode on its own.

For every mode (as MATLAB's ``damp``): natural frequency w_n = |lambda| (rad/s), damping ratio
zeta = -Re(lambda)/|lambda|.  A divergent (statically unstable) mode has zeta = -1 (lambda =
+w_n), a rigid-body mode w_n = 0 and zeta = 0.  Modes are sorted by w_n, ascending.
Shapes are columns, scaled so that the entry of largest modulus is 1.
"""
from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..output.fileio import write_atomic
from ..output.plot import save_figure


@dataclass
class Modes:
    """The modes of a linear model M x'' + C x' + K x = 0 (``Linearization.modes()``), slowest
    first: ``frequencies`` [rad/s] (``hz``), ``damping_ratios``, ``shapes`` (one column per
    mode), ``kinds`` and the eigenvalues of the first-order system."""

    coords: tuple[str, ...]
    frequencies: np.ndarray          # rad/s, ascending
    damping_ratios: np.ndarray
    shapes: np.ndarray               # (n, n_modes), real when every shape is real
    eigenvalues: np.ndarray          # all 2n eigenvalues of A (complex), sorted by modulus
    kinds: tuple[str, ...] = ()      # 'oscillatory' | 'divergent' | 'decaying' | 'rigid' per mode
    mode_eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))

    @property
    def hz(self) -> np.ndarray:
        """The frequencies in Hz (``frequencies`` / 2 pi)."""
        return self.frequencies / (2 * math.pi)

    @property
    def damped_frequencies(self) -> np.ndarray:
        """The damped frequencies [rad/s]: the imaginary parts of the modes' eigenvalues."""
        return np.abs(self.mode_eigenvalues.imag)

    def __len__(self) -> int:
        return len(self.frequencies)

    def to_dict(self) -> dict:
        """Plain JSON types: coordinates, one entry per mode (kind, frequency, damping, shape), eigenvalues."""
        modes = []
        for j in range(len(self)):
            s = self.shapes[:, j]
            m = {"index": j + 1, "kind": self.kinds[j], "frequency_rad_s": float(self.frequencies[j]),
                 "frequency_hz": float(self.hz[j]), "damping_ratio": float(self.damping_ratios[j]),
                 "eigenvalue": [float(self.mode_eigenvalues[j].real), float(self.mode_eigenvalues[j].imag)],
                 "shape": {c: float(v.real) for c, v in zip(self.coords, s)}}
            if np.iscomplexobj(s) and np.any(np.abs(s.imag) > 1e-12):
                m["shape_imag"] = {c: float(v.imag) for c, v in zip(self.coords, s)}
            modes.append(m)
        return {"coordinates": list(self.coords), "modes": modes,
                "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues]}

    def to_json(self) -> str:
        """``to_dict()`` as JSON text."""
        return json.dumps({"generator": "mechdsl", **self.to_dict()}, indent=2) + "\n"

    def to_csv_text(self) -> str:
        """One CSV row per mode: kind, frequency (rad/s, Hz), damping ratio, eigenvalue, shape."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        cplx = np.iscomplexobj(self.shapes) and np.any(np.abs(self.shapes.imag) > 1e-12)
        head = ["mode", "kind", "frequency_rad_s", "frequency_hz", "damping_ratio", "eigenvalue_re",
                "eigenvalue_im"] + [f"shape({c})" for c in self.coords]
        if cplx:
            head += [f"shape_imag({c})" for c in self.coords]
        w.writerow(head)
        for j in range(len(self)):
            s = self.shapes[:, j]
            row = [j + 1, self.kinds[j], repr(float(self.frequencies[j])), repr(float(self.hz[j])),
                   repr(float(self.damping_ratios[j])), repr(float(self.mode_eigenvalues[j].real)),
                   repr(float(self.mode_eigenvalues[j].imag))] + [repr(float(v.real)) for v in s]
            if cplx:
                row += [repr(float(v.imag)) for v in s]
            w.writerow(row)
        return buf.getvalue()

    def in_coordinates(self, basis: np.ndarray, coords) -> "Modes":
        """The same modes with shapes mapped by dq = basis dz into ``coords`` (constrained
        models: from the reduced coordinates to the original ones), rescaled to a largest entry 1."""
        S = np.asarray(basis) @ self.shapes if len(self) else np.zeros((len(coords), 0))
        S = np.array([_normalize(S[:, j]) for j in range(S.shape[1])]).T if S.shape[1] else S
        if S.size and np.max(np.abs(S.imag), initial=0.0) <= 1e-10:
            S = S.real
        return Modes(coords=tuple(coords), frequencies=self.frequencies, damping_ratios=self.damping_ratios,
                     shapes=S, eigenvalues=self.eigenvalues, kinds=self.kinds,
                     mode_eigenvalues=self.mode_eigenvalues)

    def write_json(self, path, overwrite: bool = False):
        """Write ``to_json()`` atomically (an existing file not of mechdsl's only with overwrite)."""
        return write_atomic(path, self.to_json(), overwrite=overwrite)

    def write_csv(self, path, overwrite: bool = False):
        """Write ``to_csv_text()`` atomically (an existing file not of mechdsl's only with overwrite)."""
        return write_atomic(path, self.to_csv_text(), overwrite=overwrite)

    def plot(self, path, title: str = "", overwrite: bool = False):
        """Bar chart of each mode shape (one panel per mode), written atomically."""
        from matplotlib.figure import Figure  # no pyplot: no global backend or figure registry

        k = max(1, len(self))
        fig = Figure(figsize=(max(4.0, 0.9 * len(self.coords) + 2.5), 1.9 * k + 0.6))
        axes = fig.subplots(k, 1, squeeze=False)
        x = np.arange(len(self.coords))
        for j, ax in enumerate(axes[:, 0]):
            if j >= len(self):
                ax.axis("off")
                continue
            s = self.shapes[:, j]
            ax.bar(x, np.real(s), color="tab:blue", label="Re")
            if np.iscomplexobj(s) and np.any(np.abs(s.imag) > 1e-12):
                ax.bar(x, np.imag(s), color="tab:orange", alpha=0.5, label="Im")
                ax.legend(fontsize=7)
            ax.axhline(0, color="k", lw=0.6)
            ax.set_xticks(x, self.coords, fontsize=8)
            ax.set_ylim(-1.1, 1.1)
            ax.set_title(f"mode {j + 1} ({self.kinds[j]}): {self.frequencies[j]:.5g} rad/s = "
                         f"{self.hz[j]:.5g} Hz, zeta = {self.damping_ratios[j]:.3g}", fontsize=9)
        if title:
            fig.suptitle(title, fontsize=10)
        fig.tight_layout()

        return save_figure(fig, path, overwrite=overwrite)


def modes_of(M, C, K, A, coords) -> Modes:
    n = M.shape[0]
    scale = max(np.max(np.abs(K), initial=0.0), np.max(np.abs(C), initial=0.0), 1e-300)
    conservative = (np.max(np.abs(C), initial=0.0) <= 1e-12 * scale
                    and np.max(np.abs(K - K.T), initial=0.0) <= 1e-10 * scale)
    if n == 0:
        return Modes(tuple(coords), np.zeros(0), np.zeros(0), np.zeros((0, 0)), np.zeros(0, complex), ())
    if conservative:
        from scipy.linalg import LinAlgError, eigh

        try:
            w2, phi = eigh(0.5 * (K + K.T), 0.5 * (M + M.T))
        except LinAlgError:          # M not positive definite: the general route below
            conservative = False
    if conservative:
        wscale = max(np.max(np.abs(w2), initial=0.0), 1e-300)
        freqs, zetas, kinds, lam_m, eig = [], [], [], [], []
        for v in w2:
            if abs(v) <= 1e-10 * wscale:
                freqs.append(0.0), zetas.append(0.0), kinds.append("rigid"), lam_m.append(0j)
                eig += [0j, 0j]
            elif v > 0:
                w = math.sqrt(v)
                freqs.append(w), zetas.append(0.0), kinds.append("oscillatory"), lam_m.append(1j * w)
                eig += [1j * w, -1j * w]
            else:
                s = math.sqrt(-v)
                freqs.append(s), zetas.append(-1.0), kinds.append("divergent"), lam_m.append(s + 0j)
                eig += [s + 0j, -s + 0j]
        shapes = np.array([_normalize(phi[:, j]).real for j in range(n)]).T
        return _sorted(coords, freqs, zetas, shapes, np.array(eig), kinds, lam_m)

    lam, vec = np.linalg.eig(A)
    lscale = max(np.max(np.abs(lam), initial=0.0), 1e-300)
    freqs, zetas, kinds, shapes, lam_m = [], [], [], [], []
    for j, v in enumerate(lam):
        if v.imag < -1e-10 * lscale:
            continue                           # the conjugate of a listed pair
        wn = abs(v)
        if wn <= 1e-10 * lscale:
            z, kind, wn = 0.0, "rigid", 0.0
        else:
            z = -v.real / wn
            if abs(v.imag) > 1e-10 * lscale:
                kind = "oscillatory"
            else:
                kind = "divergent" if v.real > 0 else "decaying"
        freqs.append(wn), zetas.append(z), kinds.append(kind), lam_m.append(complex(v))
        shapes.append(_normalize(vec[:n, j]))
    S = np.array(shapes).T
    if np.max(np.abs(S.imag), initial=0.0) <= 1e-10:
        S = S.real
    return _sorted(coords, freqs, zetas, S, lam, kinds, lam_m)


def _normalize(s: np.ndarray) -> np.ndarray:
    s = np.asarray(s, complex)
    i = int(np.argmax(np.abs(s)))
    if abs(s[i]) == 0:
        return s
    s = s / s[i]
    s[np.abs(s.real) < 1e-13] = 1j * s[np.abs(s.real) < 1e-13].imag
    return s


def _sorted(coords, freqs, zetas, shapes, eig, kinds, lam_m) -> Modes:
    order = sorted(range(len(freqs)), key=lambda j: (round(freqs[j], 12), zetas[j], j))
    eig = np.asarray(eig, complex)
    eig = eig[np.lexsort((eig.imag, np.abs(eig)))]
    return Modes(coords=tuple(coords), frequencies=np.array([freqs[j] for j in order], float),
                 damping_ratios=np.array([zetas[j] for j in order], float),
                 shapes=np.asarray(shapes)[:, order] if len(order) else np.zeros((len(coords), 0)),
                 eigenvalues=eig, kinds=tuple(kinds[j] for j in order),
                 mode_eigenvalues=np.array([lam_m[j] for j in order], complex))
