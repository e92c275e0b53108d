"""A rig's n lumped masses in SI, and the dimensionless n-DOF model they are (docs/rig.md,
"A rig with n masses"; issue 32).

A rig file with ``masses`` describes n lumped masses (a diagonal mass matrix M, kg), their
stiffness (a chain of ``springs`` ground - m0 - m1 - ... or a ``stiffness`` matrix K, N/m),
the modal ``damping_ratios`` zeta_i of its n modes (the damping a lab measures: a ring-down
or the half-power bandwidth of each resonance; a damping matrix is never measured
directly), the ``impacting`` mass that meets the stop, the mass the actuator pushes and the
masses the sensor measures:

    M x'' + C x' + K x = f cos(Omega t + phi),   x_w < g;   v_w+ = -r v_w-  at x_w = g.

The modal damping is C = M Phi diag(2 zeta_i omega_i) Phi^T M with K Phi = M Phi
diag(omega_i^2) and Phi^T M Phi = I (then Phi^T C Phi = diag(2 zeta_i omega_i): each mode
decays with its own ratio).

The scales are those of the 1-DOF rig (plant/rig.py) for the reference oscillator, the
impacting mass w on its own springs with the others held: m_ref = M_ww, k_ref = K_ww,
omega_n = sqrt(k_ref / m_ref), l = F0 / k_ref, tau = omega_n t, x = l x~. Dividing the
equation by k_ref l = F0 gives the model of docs/ndof_model.md:

    M~ = M / m_ref,  K~ = K / k_ref,  C~ = C / sqrt(k_ref m_ref),  f~ = f / F0,
    omega = Omega / omega_n,  d = g / l,  Delta d = d - d*(M~, C~, K~, f~, omega),

with f = F0 e_j for a force on mass j and f = Omega^2 Y M 1 for a base excitation of the
frame carrying the springs to ground and the stop (relative coordinates: M x'' + C x' +
K x = -M 1 y''), F0 = m_ref Omega^2 Y. For n = 1 these are plant/rig.py's scales and
M~ = K~ = 1, C~ = 2 zeta, f~ = 1.

The kick: the model's correction Delta v~ on the actuated coordinate a is the velocity
change of mass a; an impulse J on mass a changes the velocities by M^-1 e_a J, so
Delta v_a = (M^-1)_aa J and J = m_a Delta v_a with the effective mass m_a = 1 / (M^-1)_aa
(= M_aa for lumped masses). In SI Delta v_a = omega_n l Delta v~; as a pulse of width w
its force is m_a Delta v_a / w.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dataclasses import replace

import numpy as np

from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.plant.rig_fields import RigError, _index, _list, _number, _one_of, _q
from grazing_control.support.units import format_quantity

__all__ = ["Structure", "MAX_MASSES", "modes", "modal_damping", "modal_ratios",
           "chain_stiffness", "read_masses", "read_indices", "write_structure",
           "rig_with_ndof_model", "ONE_MASS", "N_MASSES"]

TWO_PI = 2.0 * math.pi
#: The fields of the one-mass form (plant/rig.py), refused beside ``masses``.
ONE_MASS = ("mass", "natural_frequency", "damping_ratio", "damping")
#: The top fields of the n-mass form, refused without ``masses``.
N_MASSES = ("springs", "damping_ratios", "impacting")

#: Most masses a rig file may have (the n-DOF model's work grows like n^3 per sample).
MAX_MASSES = 12


@dataclass(frozen=True)
class Structure:
    """The n >= 2 lumped masses of a rig (module docstring): ``masses`` (kg),
    ``stiffness`` K (rows, N/m), ``damping_ratios`` of the modes in ascending frequency,
    ``impacting`` (the mass at the stop), ``actuated`` (the mass the actuator pushes),
    ``measured`` (the masses the sensor measures, in the sensor's order), ``forced`` (the
    mass a force forcing acts on; a base excitation drives them all). Indices 0-based."""

    masses: tuple
    stiffness: tuple
    damping_ratios: tuple
    impacting: int
    actuated: int
    measured: tuple
    forced: int

    @property
    def n(self) -> int:
        return len(self.masses)

    @property
    def M(self) -> np.ndarray:
        """The diagonal mass matrix (kg)."""
        return np.diag(np.array(self.masses, dtype=float))

    @property
    def K(self) -> np.ndarray:
        """The stiffness matrix (N/m)."""
        return np.array(self.stiffness, dtype=float)

    @property
    def C(self) -> np.ndarray:
        """The damping matrix (N s/m) of the modal ratios (:func:`modal_damping`)."""
        return modal_damping(self.M, self.K, self.damping_ratios)

    @property
    def effective_mass(self) -> float:
        """m_a = 1 / (M^-1)_aa (kg): the impulse m_a Delta v changes v_a by Delta v."""
        return 1.0 / float(np.linalg.inv(self.M)[self.actuated, self.actuated])


def chain_stiffness(springs) -> list:
    """K of the chain ground -k0- m0 -k1- m1 - ... -k_{n-1}- m_{n-1} (N/m): K_ii = k_i +
    k_{i+1} (k_n = 0), K_{i,i+1} = -k_{i+1}."""
    n = len(springs)
    K = [[0.0] * n for _ in range(n)]
    for i, k in enumerate(springs):
        K[i][i] += k
        if i > 0:
            K[i - 1][i - 1] += k
            K[i - 1][i] -= k
            K[i][i - 1] -= k
    return K


def modes(M: np.ndarray, K: np.ndarray) -> tuple:
    """(omega_i ascending, Phi) with K Phi = M Phi diag(omega_i^2), Phi^T M Phi = I, for a
    diagonal positive M and a symmetric positive definite K (the generalised eigenproblem
    made symmetric by M^-1/2: S = M^-1/2 K M^-1/2 = U diag(omega^2) U^T, Phi = M^-1/2 U)."""
    s = 1.0 / np.sqrt(np.diag(M))
    lam, U = np.linalg.eigh(s[:, None] * K * s[None, :])
    return np.sqrt(lam), s[:, None] * U


def modal_damping(M: np.ndarray, K: np.ndarray, ratios) -> np.ndarray:
    """C = M Phi diag(2 zeta_i omega_i) Phi^T M (module docstring), symmetrised."""
    omega, Phi = modes(M, K)
    B = M @ Phi
    C = B @ np.diag(2.0 * np.asarray(ratios, dtype=float) * omega) @ B.T
    return 0.5 * (C + C.T)


def modal_ratios(M: np.ndarray, K: np.ndarray, C: np.ndarray) -> tuple:
    """(zeta_i, off): the modal ratios zeta_i = (Phi^T C Phi)_ii / (2 omega_i) of a damping
    matrix and how far it is from classical damping, max |off-diagonal of Phi^T C Phi| /
    max |diagonal| (0 up to rounding for a C of :func:`modal_damping`)."""
    omega, Phi = modes(M, K)
    D = Phi.T @ C @ Phi
    diag = np.diag(D)
    off = D - np.diag(diag)
    scale = float(np.max(np.abs(diag))) if diag.size else 1.0
    return tuple(float(z) for z in diag / (2.0 * omega)), \
        float(np.max(np.abs(off)) / scale) if scale > 0.0 else math.inf


# ---------------------------------------------------------------------- the rig file
def read_masses(doc) -> tuple:
    """(m_ref, omega_n, zeta_ref, (masses, K, ratios, impacting)) of the n-mass form
    (plant/rig_structure.py): masses, springs or stiffness, damping_ratios, impacting."""
    given = [k for k in ONE_MASS if doc.get(k) is not None]
    if given:
        raise RigError(f"{given[0]} is a field of the one-mass form: with masses give "
                       "springs or stiffness, damping_ratios and impacting")
    items = doc.get("masses")
    if not isinstance(items, list) or not 1 <= len(items) <= MAX_MASSES:
        raise RigError(f"masses={items!r} is invalid: valid is a list of 1 to {MAX_MASSES} "
                       "masses with their unit (e.g. ['0.8 kg', '0.5 kg'])")
    n = len(items)
    masses = [_q({f"masses[{i}]": v}, "", f"masses[{i}]", "mass", ok=lambda v: v > 0.0,
                 valid=f"masses[{i}] > 0") for i, v in enumerate(items)]
    if _one_of(doc, "", "springs", "stiffness") == "springs":
        springs = [_q({f"springs[{i}]": v}, "", f"springs[{i}]", "stiffness",
                      ok=lambda v: v > 0.0, valid=f"springs[{i}] > 0 (spring {i} holds mass "
                      f"{i} to {'the ground' if i == 0 else f'mass {i - 1}'})")
                   for i, v in enumerate(_list(doc, "springs", n))]
        K = chain_stiffness(springs)
    else:
        rows = _list(doc, "stiffness", n)
        K = []
        for i, row in enumerate(rows):
            if not isinstance(row, list) or len(row) != n:
                raise RigError(f"stiffness[{i}]={row!r} is invalid: expected a row of {n} "
                               "stiffnesses with their unit (an n x n matrix)")
            K.append([_q({f"stiffness[{i}][{j}]": v}, "", f"stiffness[{i}][{j}]",
                         "stiffness") for j, v in enumerate(row)])
        Ka = np.array(K)
        if not np.allclose(Ka, Ka.T, rtol=1e-12, atol=0.0):
            raise RigError("stiffness is invalid: the matrix must be symmetric")
        if not np.linalg.eigvalsh(Ka)[0] > 0.0:
            raise RigError("stiffness is invalid: the matrix must be positive definite (every "
                           "mode held by a spring: valid range is eigenvalues > 0 N/m)")
    ratios = [_number({f"damping_ratios[{i}]": v}, f"damping_ratios[{i}]",
                      lambda v: 0.0 < v < 1.0, f"0 < damping_ratios[{i}] < 1 (mode {i}, "
                      "in ascending frequency)")
              for i, v in enumerate(_list(doc, "damping_ratios", n))]
    w = _index(doc, "", "impacting", n, 0 if n == 1 else None)
    m_ref, k_ref = masses[w], K[w][w]
    omega_n = math.sqrt(k_ref / m_ref)
    if n == 1:
        return m_ref, omega_n, ratios[0], None
    c_ref = float(modal_damping(np.diag(masses), np.array(K), ratios)[w, w])
    return m_ref, omega_n, c_ref / (2.0 * math.sqrt(k_ref * m_ref)), \
        (tuple(masses), tuple(tuple(row) for row in K), tuple(ratios), w)


def read_indices(doc, f, s, a, chain) -> Structure | None:
    """The Structure of an n-mass rig: forcing.mass, actuator.mass, sensor.masses (each
    the impacting mass if not given); for one mass each may only be 0."""
    n = 1 if chain is None else len(chain[0])
    w = 0 if chain is None else chain[3]
    forced = _index(f, "forcing.", "mass", n, w)
    if f.get("mass") is not None and f.get("type", "force") == "base":
        raise RigError("forcing.mass is a force's field: a base excitation drives every "
                       "mass through the frame; remove it for forcing.type base")
    actuated = _index(a, "actuator.", "mass", n, w)
    items = s.get("masses", [w])
    if not isinstance(items, list) or not items:
        raise RigError(f"sensor.masses={items!r} is invalid: expected a list of mass indices "
                       f"(0 <= i < {n}), each once")
    measured = tuple(_index({f"masses[{j}]": v}, "sensor.", f"masses[{j}]", n, None)
                     for j, v in enumerate(items))
    if len(set(measured)) != len(measured):
        raise RigError(f"sensor.masses={items!r} is invalid: each mass index once")
    if chain is None:
        return None
    masses, K, ratios, w = chain
    return Structure(masses, K, ratios, w, actuated, measured, forced)


def write_structure(st: Structure, out: dict) -> None:
    """The n-mass form's fields in ``out`` (a one-mass mapping of :func:`rig_to_dict`)."""
    q = format_quantity
    for key in ONE_MASS:
        out.pop(key, None)
    out["masses"] = [q(m, "mass") for m in st.masses]
    out["stiffness"] = [[q(k, "stiffness") for k in row] for row in st.stiffness]
    out["damping_ratios"] = list(st.damping_ratios)
    out["impacting"] = st.impacting
    if out["forcing"]["type"] == "force":
        out["forcing"]["mass"] = st.forced
    out["actuator"]["mass"] = st.actuated
    out["sensor"]["masses"] = list(st.measured)


def rig_with_ndof_model(rig, model: NdofModel):
    """The inverse of :meth:`Rig.model` (plant/rig_structure.py): the reference mass
    m_ref (weighed), the forcing frequency, amplitude and phase, the sensor and actuator
    stay; omega_n = Omega / omega, k_ref = m_ref omega_n^2, M = m_ref M~, K = k_ref K~,
    C = sqrt(k_ref m_ref) C~ written as its modal ratios, gap = (d* + Delta d) l with
    l = F0 / k_ref. RigError for a model the rig file cannot write: another n, a mass
    matrix that is not diagonal, a damping that is not modal, a forcing that is not the
    rig's (f~ = e_j of the forced mass, or M~ 1 for a base excitation)."""
    from grazing_control.oscillator.ndof.flow import grazing_clearance

    st = rig.structure
    if st is None or model.n != st.n or model.i_w != st.impacting:
        raise RigError(f"the model (n = {model.n}, i_w = {model.i_w}) is not of this rig "
                       f"(n = {rig.n}, impacting mass {0 if st is None else st.impacting})")
    if not np.array_equal(model.M, np.diag(np.diag(model.M))):
        raise RigError("the model's M is not diagonal: a rig file has lumped masses")
    omega_n = TWO_PI * rig.frequency / model.omega
    m_ref = rig.mass / float(model.M[st.impacting, st.impacting])
    k_ref = m_ref * omega_n ** 2
    M = m_ref * model.M
    K = k_ref * model.K
    C = math.sqrt(k_ref * m_ref) * model.C
    ratios, off = modal_ratios(M, K, C)
    if not off <= 1e-9:
        raise RigError(f"the model's C is not modal damping (Phi^T C Phi off-diagonal "
                       f"{off:.3g} of its diagonal): a rig file gives damping_ratios")
    new = replace(rig, mass=m_ref, omega_n=omega_n, restitution=model.r,
                  pi2_offset=model.pi2_offset,
                  structure=replace(st, masses=tuple(float(m) for m in np.diag(M)),
                                    stiffness=tuple(tuple(float(k) for k in row) for row in K),
                                    damping_ratios=ratios, actuated=model.i_a))
    f_rig = rig.model().f
    if not np.allclose(model.f, f_rig, rtol=1e-12, atol=1e-15):
        raise RigError(f"the model's f = {model.f.tolist()} is not this rig's forcing "
                       f"{f_rig.tolist()}")
    c_ref = float(new.structure.C[st.impacting, st.impacting])
    new = replace(new, zeta=c_ref / (2.0 * math.sqrt(k_ref * m_ref)))
    d = grazing_clearance(model) + model.delta_d
    return replace(new, gap=d * new.scales.length)
