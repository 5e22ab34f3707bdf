"""Stage 2, contact detection (coal): per declared pair, the contact points, normals and gaps.

The driver (:mod:`.driver`, after MJX's ``collision_driver.py``) sends each pair to the routine of
its geometry-pair type: polyhedra, spheres and capsules on a ground plane to one compiled pass
(:mod:`.ground`), boxes against boxes to a compiled separating-axis test and face clipping
(:mod:`.boxes`), spheres, capsules and boxes against each other to coal's closed forms and contact
patch, compiled (:mod:`.primitives`), every other pair to coal's narrow phase and contact patch
(:mod:`.narrow`), the last three behind a bounding-sphere broad phase over all their pairs at once
(the compiled ones share :mod:`.compiled`).
:mod:`.margin` schedules the margin and says when a step need not look; :mod:`.contacts` holds the
record the routines fill.
"""

from .contacts import NO_CONTACTS, PATCH_MIN_EXTENT, PATCH_TOLERANCE, Contacts
from .driver import ContactDetector

__all__ = ["NO_CONTACTS", "PATCH_MIN_EXTENT", "PATCH_TOLERANCE", "ContactDetector", "Contacts"]
