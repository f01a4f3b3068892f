"""Peabody: Jack's figure/environment representation (seed 000, chapters 7-8), rebuilt on numpy.

``model`` (the objects), ``language`` (parser), ``values`` (units, transforms, DOFs), ``loader`` (read
``.fig`` and ``.env`` files), ``writer`` (write them), ``psurf`` (``.pss`` geometry), ``fk`` (batched
forward kinematics and the project-wide pose-vector layout).  ``docs/PEABODY.md`` describes the language.
"""
