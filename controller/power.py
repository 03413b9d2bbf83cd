"""The finite-time power law of the virtual controls, regularised near zero.

The paper's term (1/e) c V^alpha with V = e^2/2 (eq. 17, 29, 36, 38, 40) equals
c 2^-alpha sig_beta(e) with sig_beta(e) = |e|^beta sign(e) and beta = 2 alpha - 1
(docs/law.md, "The finite-time step"). Its derivatives are unbounded at e = 0, and the backstepping needs
three of them, so the exact law diverges in simulation.

Regularisation (deviation from the paper, docs/law.md, "Regularised power sig_β"): inside
|e| < eps, sig_beta is replaced by the odd polynomial
    eps^beta * (a1 u + a3 u^3 + a5 u^5 + a7 u^7),   u = e / eps,
whose value and first three derivatives match |e|^beta sign(e) at |e| = eps (C^3 join).
Outside the band the law is exactly the paper's, so the finite-time bound of eq. (11)/(19)
holds unchanged until the error enters the band. The polynomial is strictly increasing
for every beta in (0, 1) (tested), so the regularised law still drives e to 0.

In:  beta = 2 alpha - 1 in (0, 1), eps > 0 (the loop's units: m, m/s or rad), an error e (same units)
Out: sig_beta(e) and its first three derivatives with respect to e; :func:`sig_table` packs (beta, eps)
     and the join's coefficients into the plain tuple :func:`sig_derivs` (the kernel the law and the
     batch engine share) reads
"""

from __future__ import annotations

import numpy as np

from controller.jets import Jet, chain

_JOIN = np.array([[1, 1, 1, 1], [1, 3, 5, 7], [0, 6, 20, 42], [0, 6, 60, 210]], dtype=float)
SigTable = tuple[float, float, float, float, float, float, float, float, float, float]


def sig_table(beta: float, eps: float) -> SigTable:
    """(beta, eps, a1, a3, a5, a7, s0, s1, s2, s3): the C^3 join's coefficients a1..a7 (the polynomial
    matches |e|^beta sign(e) and three derivatives at |e| = eps) and the scales s_k = eps^(beta - k)."""
    if not 0.0 < beta < 1.0:
        raise ValueError(f"beta must be in (0, 1), got {beta}")
    if eps <= 0.0:
        raise ValueError(f"eps must be positive, got {eps}")
    b = beta
    rhs = np.array([1.0, b, b * (b - 1.0), b * (b - 1.0) * (b - 2.0)])
    a1, a3, a5, a7 = (float(v) for v in np.linalg.solve(_JOIN, rhs))
    return (beta, eps, a1, a3, a5, a7, *(eps ** (beta - k) for k in range(4)))  # type: ignore[return-value]


def sig_derivs(e: float, P: SigTable) -> tuple[float, float, float, float]:
    """sig_beta(e) and its first three derivatives at e (module docstring; eq. 17/29 with c' folded out),
    P = :func:`sig_table`. Plain floats: the batch engine compiles this same function."""
    b = P[0]
    eps = P[1]
    if e >= eps or e <= -eps:
        m = abs(e)
        p = m**b
        f1 = b * p / m
        f2 = (b - 1.0) * f1 / m
        f3 = (b - 2.0) * f2 / m
        return (p, f1, f2, f3) if e > 0.0 else (-p, f1, -f2, f3)
    a1, a3, a5, a7, s0, s1, s2, s3 = P[2], P[3], P[4], P[5], P[6], P[7], P[8], P[9]
    u = e / eps
    u2 = u * u
    return (
        s0 * u * (a1 + u2 * (a3 + u2 * (a5 + u2 * a7))),
        s1 * (a1 + u2 * (3.0 * a3 + u2 * (5.0 * a5 + u2 * 7.0 * a7))),
        s2 * u * (6.0 * a3 + u2 * (20.0 * a5 + u2 * 42.0 * a7)),
        s3 * (6.0 * a3 + u2 * (60.0 * a5 + u2 * 210.0 * a7)),
    )


class SignedPower:
    """sig_beta(e) = |e|^beta sign(e), C^3-regularised inside |e| < eps (see module doc)."""

    __slots__ = ("beta", "eps", "table")

    def __init__(self, beta: float, eps: float) -> None:
        self.table = sig_table(beta, eps)
        self.beta = beta
        self.eps = eps

    def derivs(self, e: float) -> tuple[float, float, float, float]:
        """sig_beta and its first three derivatives at e (:func:`sig_derivs`)."""
        return sig_derivs(e, self.table)

    def __call__(self, e: float) -> float:
        return sig_derivs(e, self.table)[0]

    def jet(self, a: Jet) -> Jet:
        """sig_beta applied to a jet (chain rule)."""
        f0, f1, f2, f3 = sig_derivs(a[0], self.table)
        return chain(f0, f1, f2, f3, a)
