"""
Pressure cavities condensed per segment onto its two frames (the online cavity model).

Each skinned segment cavity (:mod:`cbha_inverse.core.actuation.cavities`) is, like the
compliance of the segment, reduced to its two frames: the wrench on the upper frame per unit
pressure is affine in the corotational deformation of the segment, ``G(δ) ≈ G0 + H δ``
(frame-i axes), fitted by
central differences of the exact skinned mesh at rest, and the lower frame receives the
equilibrating wrench (a closed cavity exerts no net wrench). One small operation per segment
instead of one per vertex; error second order in the segment deformation (tested against the
mesh). The affine model's wrench and exact load stiffness are evaluated by the compiled link
pass (:func:`cbha_inverse.core._kernels.links.link_pass`, which needs every part to carry the rest
geometry of its link); the numpy version is a test oracle (``test/oracles/actuation.py``).
"""

from cbha_inverse.core.actuation.cavities import Cavity, CavityGroup, CavityPart
from cbha_inverse.core.so3 import so3_exp
import numpy as np


class LinearCavityGroup:
    """
    Cavities condensed per segment onto the two frames (affine in the segment deformation).

    Parameters
    ----------
    cavities : sequence of Cavity
        The pressure actuators, in column order.
    n_frames : int
        Number of frames (base included).
    step : float
        Relative finite-difference step of the fit (times the segment length for translations,
        radians for rotations).

    """

    def __init__(self, cavities, n_frames, step=1e-5):
        """Fit ``G0``, ``H`` and the volume of every segment part from the exact mesh."""
        self.cavities = tuple(cavities)
        self.names = tuple(c.name for c in self.cavities)
        self.n_frames = int(n_frames)
        lower, owner, g0, hess, d0, q0, v0 = [], [], [], [], [], [], []
        for j, cavity in enumerate(self.cavities):
            for part in cavity.parts:
                g, h, vol = _shared_fit(part, step)
                lower.append(part.lower)
                owner.append(j)
                # the cavity's gain (calibration) scales its wrench per Pa and its volume
                g0.append(cavity.gain * g)
                hess.append(cavity.gain * h)
                d0.append(np.asarray(part.rest_offset, dtype=float))
                q0.append(np.asarray(part.rest_rotation, dtype=float))
                v0.append(cavity.gain * vol)
        self.lower = np.array(lower, dtype=int)
        self.upper = self.lower + 1
        self.g0 = np.array(g0)
        self.hessian = np.array(hess)
        self.rest_offset = np.array(d0)
        self.rest_rotation = np.array(q0)
        self.v0 = np.array(v0)
        self.owner = np.array(owner, dtype=int)
        self.upper_bounds = np.array([c.max_pressure for c in self.cavities], dtype=float)
        self.lower_bounds = np.zeros(len(self.cavities))

    @property
    def n_actuators(self):
        """Return the number of cavities."""
        return len(self.cavities)


_FITS = {}
"""Fits by part geometry and step (:func:`_shared_fit`)."""
_MAX_FITS = 256


def _shared_fit(part, step):
    """
    Return :func:`fit_linear_cavity` of the part, computed once per geometry and step.

    The fit depends only on the part's geometry (not on its link, its cavity's gain or the
    calibration): the repeated segments of a section share it (the CBHA: 3 fits instead of 48
    per scene load), and so do the scene loads of one process, e.g. one per model evaluation of
    ``cbha_identify`` (a CBHA load then takes 11 ms instead of 53 ms). The cached arrays are
    read-only.
    """
    key = (float(step),) + tuple(np.ascontiguousarray(a, dtype=float).tobytes() for a in (
        part.points, part.triangles, part.rest_offset, part.rest_rotation))
    fit = _FITS.get(key)
    if fit is None:
        g, h, volume = fit_linear_cavity(part, step)
        g.flags.writeable = h.flags.writeable = False
        if len(_FITS) >= _MAX_FITS:
            _FITS.clear()
        fit = _FITS[key] = (g, h, volume)
    return fit


def fit_linear_cavity(part, step=1e-5):
    """
    Fit the affine upper-frame wrench ``G(δ) ≈ G0 + H δ`` of one skinned segment cavity.

    Frame ``i`` is held at the identity and frame ``j`` is placed at ``x = d0 + δ_lin``,
    ``R = exp(δ_ang) Q0``; ``G`` is the exact mesh wrench on frame ``j`` per unit pressure (frame-i
    axes) and ``H`` its central-difference derivative.

    Parameters
    ----------
    part : CavityPart
        The segment cavity.
    step : float
        Relative step (times ``|d0|`` for translations, radians for rotations).

    Returns
    -------
    g0 : (6,) ndarray
        Wrench on the upper frame at rest.
    hessian : (6, 6) ndarray
        ``dG/dδ``.
    volume : float  [m^3]
        Rest volume.

    """
    local = CavityPart(part.points, part.triangles, 0, part.rest_offset, part.rest_rotation)
    group = CavityGroup([Cavity('part', (local,), np.inf)], 2)
    d0 = np.asarray(part.rest_offset, dtype=float)
    q0 = np.asarray(part.rest_rotation, dtype=float)
    scale = np.array([np.linalg.norm(d0)] * 3 + [1.0] * 3) * step

    def upper_wrench(delta):
        positions = np.stack([np.zeros(3), d0 + delta[:3]])
        rotations = np.stack([np.eye(3), so3_exp(delta[3:]) @ q0])
        wrenches, volume = group.evaluate(positions, rotations)
        return wrenches[0, 1], volume[0]

    g0, volume = upper_wrench(np.zeros(6))
    hessian = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = scale[k]
        hessian[:, k] = (upper_wrench(e)[0] - upper_wrench(-e)[0]) / (2.0 * scale[k])
    return g0, hessian, float(volume)
