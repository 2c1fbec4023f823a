"""
Assembly of the chain's internal wrenches and block-tridiagonal tangent stiffness.

Frames 1..n move (frame 0 is the fixed base). Link i joins frame i to frame i+1, so frame j
(1-based) receives the b-side wrench of link j-1 and the a-side wrench of link j; the global
tangent is block tridiagonal with 6x6 blocks (paper §III, Fig. 1). Everything is vectorised over
the links (no Python loop per link).
"""

from dataclasses import dataclass

from cbha_inverse.core.links import (link_terms, local_material_tangent, local_tangent,
                                     rotate_tangent, wrench_pair_from_terms)
from cbha_inverse.core.se3 import hat
import numpy as np


@dataclass(frozen=True, eq=False)
class TangentSystem:
    """
    Internal wrenches and symmetric block-tridiagonal tangent of a chain at one state.

    Attributes
    ----------
    internal : (n, 6) ndarray  [N, N*m]
        Total link wrench on frames 1..n, world axes, at each frame origin (paper eq. 9, f(q)).
    diagonal : (n, 6, 6) ndarray
        Symmetric diagonal blocks of ``K = -d internal / d increments`` (world-axis increments).
    upper : (n - 1, 6, 6) ndarray
        ``upper[i]`` = block (i, i+1) of frames 1..n; block (i+1, i) is its transpose (exact).

    Notes
    -----
    The exact derivative differs from the symmetric tangent only by the antisymmetric part
    ``hat(m_j) / 2`` of the rotational 3x3 part of diagonal block j, ``m_j`` the internal moment
    on frame j (see :attr:`exact_diagonal`). It vanishes at an equilibrium without applied
    moments, so Newton with the symmetric tangent stays quadratic there.

    """

    internal: np.ndarray
    diagonal: np.ndarray
    upper: np.ndarray

    @property
    def exact_diagonal(self):
        """Return the exact (non-symmetric) diagonal blocks, (n, 6, 6)."""
        out = self.diagonal.copy()
        out[:, 3:, 3:] += 0.5 * hat(self.internal[:, 3:])
        return out

    def to_dense(self, exact=False):
        """
        Return the tangent as a dense (6n, 6n) matrix (for tests and small problems).

        Parameters
        ----------
        exact : bool
            Use :attr:`exact_diagonal` instead of the symmetric diagonal blocks.

        Returns
        -------
        (6n, 6n) ndarray

        """
        return blocks_to_dense(self.exact_diagonal if exact else self.diagonal, self.upper)


def blocks_to_dense(diagonal, upper, lower=None):
    """
    Build a dense matrix from block-tridiagonal storage.

    Parameters
    ----------
    diagonal : (n, 6, 6) array_like
        Diagonal blocks.
    upper : (n - 1, 6, 6) array_like
        Blocks (i, i+1).
    lower : (n - 1, 6, 6) array_like, optional
        Blocks (i+1, i); the transposes of ``upper`` by default.

    Returns
    -------
    (6n, 6n) ndarray

    """
    diagonal = np.asarray(diagonal, dtype=float)
    upper = np.asarray(upper, dtype=float)
    lower = np.swapaxes(upper, 1, 2) if lower is None else np.asarray(lower, dtype=float)
    n, b = diagonal.shape[:2]
    out = np.zeros((n, b, n, b))
    idx = np.arange(n)
    out[idx, :, idx, :] = diagonal
    out[idx[:-1], :, idx[1:], :] = upper
    out[idx[1:], :, idx[:-1], :] = lower
    return out.reshape(n * b, n * b)


def chain_terms(model, state):
    """
    Evaluate the local terms of all links of a chain (shared by wrenches and tangent).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.

    Returns
    -------
    LinkTerms
        Batched over the n links.

    """
    pos = state.positions
    rot = state.rotations
    terms = link_terms(model.stiffnesses, model.rest_offsets, model.rest_rotations,
                       pos[:-1], rot[:-1], pos[1:], rot[1:])
    return terms


def _gather_wrenches(w_a, w_b):
    """Sum link wrenches onto frames 1..n: frame j gets w_b of link j-1 and w_a of link j."""
    internal = w_b.copy()
    internal[:-1] += w_a[1:]
    return internal


def _gather_blocks(rotation_a, local):
    """
    Rotate link tangents to world axes and add them into the BTD blocks of frames 1..n.

    Parameters
    ----------
    rotation_a : (n, 3, 3) ndarray
        World rotations of the a-frames (frames 0..n-1).
    local : (n, 12, 12) ndarray
        Link tangents in frame-a axes.

    Returns
    -------
    diagonal : (n, 6, 6) ndarray
        Symmetrised diagonal blocks (the fixed base block dropped).
    upper : (n - 1, 6, 6) ndarray

    """
    world = rotate_tangent(rotation_a, local)
    diagonal = world[:, 6:, 6:].copy()
    diagonal[:-1] += world[1:, :6, :6]
    diagonal += np.swapaxes(diagonal, 1, 2)
    diagonal *= 0.5
    return diagonal, world[1:, :6, 6:].copy()


def internal_wrenches(model, state, terms=None):
    """
    Total link wrench on frames 1..n (the elastic force f(q) of paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    (n, 6) ndarray  [N, N*m]
        World axes, at each frame origin.

    """
    if terms is None:
        terms = chain_terms(model, state)
    w_a, w_b = wrench_pair_from_terms(terms, state.rotations[:-1])
    return _gather_wrenches(w_a, w_b)


def assemble_tangent(model, state, terms=None):
    """
    Assemble internal wrenches and the BTD tangent ``K = -d internal / d increments``.

    Per link the exact 12x12 tangent (material part, paper eq. 8, plus the geometric part; see
    :mod:`cbha_inverse.core.links`) is computed in frame-a axes, rotated to world axes and added
    into the blocks of its two frames; the block of the fixed base is dropped. The diagonal
    blocks are symmetrised (see :class:`TangentSystem`).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    TangentSystem

    """
    rot_a = state.rotations[:-1]
    if terms is None:
        terms = chain_terms(model, state)
    w_a, w_b = wrench_pair_from_terms(terms, rot_a)
    diagonal, upper = _gather_blocks(rot_a, local_tangent(terms, model.stiffnesses))
    return TangentSystem(_gather_wrenches(w_a, w_b), diagonal, upper)


def material_tangent(model, state, terms=None):
    """
    Material part of the chain tangent (paper eq. 8): symmetric positive definite BTD blocks.

    Per link ``B^T K B`` (:func:`cbha_inverse.core.links.local_material_tangent`), rotated to
    world axes and assembled over frames 1..n; no geometric (stress) part, so it stays positive
    definite whatever the loads.

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    diagonal : (n, 6, 6) ndarray
    upper : (n - 1, 6, 6) ndarray

    """
    if terms is None:
        terms = chain_terms(model, state)
    return _gather_blocks(state.rotations[:-1],
                          local_material_tangent(terms, model.stiffnesses))
