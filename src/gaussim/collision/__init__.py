"""Stage 2, contact detection (coal): per declared pair, the contact points, normals and gaps.

The driver (:mod:`.driver`, after MJX's ``collision_driver.py``) sends each pair to the routine of
its geometry-pair type: polyhedra and spheres on a ground plane to one compiled pass
(:mod:`.ground`), every other pair to coal's narrow phase and contact patch, behind a
bounding-sphere broad phase over all of them at once (:mod:`.narrow`).
:mod:`.margin` schedules the margin and says when a step need not look; :mod:`.contacts` holds the
record the routines fill.
"""

from .contacts import NO_CONTACTS, PATCH_MIN_EXTENT, PATCH_TOLERANCE, Contacts
from .driver import ContactDetector

__all__ = ["NO_CONTACTS", "PATCH_MIN_EXTENT", "PATCH_TOLERANCE", "ContactDetector", "Contacts"]
