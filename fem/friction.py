"""Friction between a rigid object and the skin: Coulomb's law, smoothed and lagged.

Beside a frictionless :class:`~fem.contact.Contact`, friction adds to the energy a dissipative
potential in each contact node's slip over one step of the object's motion (the lagged friction
of Incremental Potential Contact: Li et al. 2020, ACM Trans. Graph. 39(4) 49). At the step's
start each skin node ``i`` of the contact keeps its position ``x0_i``, its contact pressure
``lambda_i`` (Pa) and the object's normal ``n_i`` there; the object moves by ``m_i`` over the
step (the same for every node of an object pushed along one direction; a hand closing along its
path moves each point by its own). The node's slip is its motion relative to the object's,
tangent to the object:

    s_i = (I - n_i n_i^T) (x_i - x0_i - m_i),        y_i = |s_i|

and the potential

    D = sum_i mu w_i lambda_i f0(y_i),   f0'(y) = f1(y) = 2 y / eps - y^2 / eps^2 (y < eps), 1

(``w_i`` the node's share of the skin's area, m^2; ``mu`` the friction coefficient). Its
gradient is the friction force: ``mu w lambda`` (Coulomb's bound) along the slip once a node
slides more than ``eps`` (m) in the step, and a stiff spring below it (sticking: a node may
creep up to ``eps`` a step). The Hessian is positive semi-definite as it is (no projection):
``mu w lambda [f1(y) / y P + (f1'(y) - f1(y) / y) / y^2 s s^T]``, ``P`` the tangent projector.
The pressures and normals are lagged: after each of the contact's multiplier updates they are
taken afresh, and the updates go on until they stand still (:meth:`Friction.relag`).

Friction makes an answer depend on the way to it: a depth reached from a shallower answer and
one reached back from a deeper one differ (by up to the friction's share of the force).
Lengths in m, pressures in Pa, forces in N.
"""

from __future__ import annotations

import numpy as np

SLIP = 1e-5
"""``eps``, m: the slip in one step below which a node sticks (the friction force grows to
Coulomb's bound over it). A tenth of a percent of a 10 mm step of the march; smaller makes the
sticking stiffer, and Newton's steps shorter."""

SKIN_FRICTION = 0.5
"""Dry human skin's friction coefficient against smooth solids: Derler & Gerhardt (2012),
Tribol. Lett. 45:1-27, review of the published measurements: above 0.2 and typically about 0.5
for dry skin, above 1 for moist or wet skin (rising as the contact pressure falls); 450
measurements on four body sites against steel, aluminium, PE and PTFE gave a median static
coefficient of 0.52 and a dynamic one of 0.36 (Veijgen, Masen & van der Heide 2013, Tribol.
Lett. 49:251-262). Dimensionless."""


def coefficient(mu) -> float:
    """``mu`` checked: a finite friction coefficient >= 0."""
    if isinstance(mu, bool) or not isinstance(mu, (int, float, np.floating, np.integer)):
        raise ValueError(f"the friction coefficient must be a number >= 0, got {mu!r}")
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"the friction coefficient must be finite and >= 0, got {mu!r}")
    return float(mu)


REACHED = 0.01
"""How far outside a closing mesh (m) a skin point's motion is taken at the nearest point of the
mesh, at the least: a point farther out cannot be pressed within the step (the step's
largest motion of the mesh, four times over, widens it), and takes the path at a point of the
mesh near it instead. On a whole-hand grip this is 0.9 s a step in place of 10.7 s, the
motions the same to round-off."""


def motion(shape, direction, x: np.ndarray, step: float) -> np.ndarray:
    """``(K, 3)``: how far the object moves at each point ``x`` ``(K, 3)`` (m, on or near its
    surface) when pushed ``step`` (m) further: along ``direction`` ``(3,)``, or, for a mesh
    closing along its path (``direction`` ``None``), by its path at the nearest point of its
    surface (:meth:`fem.shapes.Surface.path_at`; beyond :data:`REACHED` at a point near it).
    """
    if direction is not None:
        return np.broadcast_to(step * np.asarray(direction, dtype=float), x.shape)
    fastest = 0.0 if shape.path is None else float(np.linalg.norm(shape.path, axis=1).max())
    return step * shape.path_at(x, max(REACHED, 4 * abs(step) * fastest))


class Friction:
    """Coulomb friction of coefficient ``mu`` on ``contact``'s skin nodes, as a potential the
    solver adds to its energy (see the module docstring); ``slip``: ``eps``, m.
    """

    def __init__(self, contact, mu: float, slip: float = SLIP):
        self.contact = contact
        self.mu = coefficient(mu)
        if not (np.isfinite(slip) and slip > 0):
            raise ValueError(f"the sticking slip must be > 0 m, got {slip!r}")
        self.slip = float(slip)
        k = len(contact.nodes)
        self.start = contact.rest.copy()
        self.moves = np.zeros((k, 3))
        self.normals = np.zeros((k, 3))
        self.bound = np.zeros(k)  # mu w lambda: each node's Coulomb bound, N

    def begin(self, u: np.ndarray, moves: np.ndarray) -> None:
        """A step starts at displacement ``u`` ``(n_all, 3)`` while the object moves by
        ``moves`` ``(K, 3)`` (m) at the contact's nodes: their positions are kept, and the
        pressures and normals taken from the contact as it stands.
        """
        self.start = self.contact.rest + u[self.contact.nodes]
        self.moves = np.array(moves, dtype=float)
        # the object's normals taken afresh: the contact's own are those of its last update,
        # which may belong to another state (a try marched back from a deeper answer)
        self.normals = self.contact.shape.distance(self.start)[1]
        self.bound = self.mu * self.contact.weights * self.contact.multipliers

    def relag(self) -> float:
        """Take the contact's pressures and normals as its last update left them; returns how
        much the Coulomb bounds changed, as a share of their sum (0 when nothing presses).
        """
        new = self.mu * self.contact.weights * self.contact.multipliers
        change = float(np.abs(new - self.bound).sum())
        total = float(new.sum())
        self.bound = new
        self.normals = self.contact._normals
        return change / total if total > 0 else 0.0

    def _slips(self, u: np.ndarray):
        on = self.bound > 0
        x = self.contact.rest[on] + u[self.contact.nodes[on]]
        d = x - self.start[on] - self.moves[on]
        n = self.normals[on]
        s = d - np.einsum("ki,ki->k", d, n)[:, None] * n
        return on, s, np.linalg.norm(s, axis=1), n

    def energy(self, u: np.ndarray) -> float:
        """The friction potential at displacement ``u`` ``(n_all, 3)``, J."""
        on, _, y, _ = self._slips(u)
        e = self.slip
        f0 = np.where(y < e, y**2 / e - y**3 / (3 * e**2), y - e / 3)
        return float(self.bound[on] @ f0)

    def _scale(self, y: np.ndarray) -> np.ndarray:
        """``f1(y) / y`` (1/m), its limit ``2 / eps`` at no slip."""
        e = self.slip
        return np.where(y < e, 2 / e - y / e**2, 1 / np.maximum(y, e))

    def gradient(self, u: np.ndarray) -> np.ndarray:
        """``(n_all, 3)``: the potential's gradient, N (minus the friction forces on the skin)."""
        on, s, y, _ = self._slips(u)
        out = np.zeros((self.contact.solver.n_all, 3))
        out[self.contact.nodes[on]] = (self.bound[on] * self._scale(y))[:, None] * s
        return out

    def hessian(self, u: np.ndarray):
        """The potential's Hessian node by node, ``(rows, cols, values)`` over DOF indices
        ``3 node + i``.
        """
        on, s, y, n = self._slips(u)
        e = self.slip
        P = np.eye(3) - n[:, :, None] * n[:, None, :]
        # (f1' - f1 / y) / y^2: -1 / (eps^2 y) sticking, -1 / y^3 sliding; times s s^T, which
        # vanishes as y^2
        ss = s[:, :, None] * s[:, None, :]
        turn = np.zeros_like(y)
        stick = (y > 0) & (y < e)
        turn[stick] = -1 / (e**2 * y[stick])
        turn[y >= e] = -1 / y[y >= e] ** 3
        H = self.bound[on, None, None] * (
            self._scale(y)[:, None, None] * P + turn[:, None, None] * ss
        )
        nodes = self.contact.nodes[on]
        i, k = np.divmod(np.arange(9), 3)
        rows = (3 * nodes[:, None] + i).ravel()
        cols = (3 * nodes[:, None] + k).ravel()
        return rows, cols, H.reshape(-1)

    def force(self, u: np.ndarray) -> np.ndarray:
        """``(3,)`` the friction force the skin exerts on the object at ``u``, N."""
        return self.gradient(u).sum(axis=0)
