"""Objects pressed on a body part: where they touch and how the force is shared.

:mod:`~stmpl.contact.pressing` finds the skin an object's mesh reaches at a pose (its public
names are offered here too: ``contact``, ``Pressing``, ``Contact``, ``read_mesh``,
``pose_matrix``), :mod:`~stmpl.contact.objects` builds the shapes (spheres, rods, letters,
straps) and sets them on the skin, and :mod:`~stmpl.contact.hand` poses anny's own hand in a
grip.
"""

from stmpl.lazy import exports

PUBLIC = {name: "stmpl.contact.pressing" for name in ("Contact", "Pressing", "contact")}
PUBLIC.update(pose_matrix="stmpl.contact.pressing", read_mesh="stmpl.contact.pressing")
"""The package's names and the module each comes from, imported on first use."""

__all__ = list(PUBLIC)
__getattr__, __dir__ = exports(__name__, PUBLIC)
