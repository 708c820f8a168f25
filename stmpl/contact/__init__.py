"""Objects pressed on a body part: where they touch and how the force is shared.

:mod:`~stmpl.contact.pressing` finds the skin an object's mesh reaches at a pose (its public
names are offered here too: ``contact``, ``Pressing``, ``Contact``, ``read_mesh``,
``pose_matrix``), :mod:`~stmpl.contact.objects` builds the shapes (spheres, rods, letters,
straps) and sets them on the skin, and :mod:`~stmpl.contact.hand` poses anny's own hand in a
grip.
"""

from stmpl.contact.pressing import Contact, Pressing, contact, pose_matrix, read_mesh

__all__ = ["Contact", "Pressing", "contact", "pose_matrix", "read_mesh"]
