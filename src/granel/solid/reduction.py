"""Reduced modal bases of a solid: the residual modes that stand for the eigenmodes above a
cut-off (their static compliance at the contacts, with the inertia of those shapes), and the
modes' static displacement under a preload."""

from __future__ import annotations

import numpy as np

from .base import SolidModel


def static_modes(force, P, w2, nc):
    """The interface forces (nc, 2) and the modes' static displacement eta = W^-2 P' F under a
    preload `force` (None: none), with P the contacts' modal matrix and w2 the squared frequencies."""
    F = np.zeros((nc, 2)) if force is None else np.array(force, float).reshape(nc, 2)
    eta = (P.T @ F.ravel()) / w2 if len(w2) else np.zeros(0)
    return F, eta


def residual_modes(model: SolidModel, B, shapes, keep, omega, partial: bool = False, at_contacts=None):
    """Residual modes of the dropped modes at the contacts: Rayleigh-Ritz on their static shapes
    Psi = K^-1 B' - Phi W^-2 P' (M-orthogonal to the retained modes), so that their static
    compliance at the contacts is R = B K^-1 B' - P W^-2 P' exactly, with the inertia of those
    shapes. Returns (omega_r, P_r = B Phi_r, Z, Psi) with Phi_r = Psi Z; shapes that vanish (a
    beam's tangential DOFs) are left out.

    `partial`: `shapes` holds only the modes below the cut-off (all kept), and K^-1 B' comes from a
    sparse factorisation. Otherwise `at_contacts` = (P, P_d, omega_d), the retained and dropped
    modes at the contacts, is enough: R = P_d W_d^-2 P_d' and Psi' M Psi = P_d W_d^-4 P_d', with
    no factorisation, and Psi is returned as None. docs/performance.md ("Modes") says why residual
    modes."""
    from scipy.linalg import eigh

    m2 = B.shape[0]
    if m2 == 0 or (np.all(keep) and not partial):  # every mode kept, or no contact to feel the dropped ones
        return np.zeros(0), np.zeros((m2, 0)), np.zeros((m2, 0)), np.zeros((model.ndof, 0))
    if partial:
        from scipy.sparse.linalg import splu

        Psi = splu(model.K.tocsc()).solve(B.T.toarray())
        full = np.abs(np.diag(B @ Psi)).max()  # the largest static compliance at a contact
        nk = int(np.count_nonzero(keep))
        # the modes ascend, so the retained ones are the first columns: a slice reads a
        # memory-mapped matrix only that far along each row
        Phi = np.asarray(shapes[:, :nk]) if np.all(keep[:nk]) else np.asarray(shapes[:, keep])
        Psi -= Phi @ ((B @ Phi).T / omega[:, None] ** 2)
        R = B @ Psi  # B K^-1 B' - P W^-2 P': the dropped modes' static compliance at the contacts
        mass = Psi.T @ (model.M @ Psi)
    else:
        P_k, P_d, omega_d = at_contacts
        Psi = None
        R = (P_d / omega_d**2) @ P_d.T
        mass = (P_d / omega_d**4) @ P_d.T
        full = np.abs(np.diag(R) + np.einsum("ij,ij->i", P_k / omega**2, P_k)).max()
    R = 0.5 * (R + R.T)
    # the shapes the contacts feel: R's range (a beam's tangential DOFs feel none)
    lam, V = np.linalg.eigh(R)
    V = V[:, lam > 1e-12 * full]
    G = V.T @ mass @ V
    lam, U = np.linalg.eigh(0.5 * (G + G.T))
    ok = lam > 1e-12 * lam.max() if lam.size else lam > 0
    U = V @ (U[:, ok] / np.sqrt(lam[ok]))  # Psi U: M-orthonormal
    w2, Y = eigh(U.T @ R @ U)
    Z = U @ Y
    return np.sqrt(np.maximum(w2, 0.0)), np.ascontiguousarray(R @ Z), Z, Psi
