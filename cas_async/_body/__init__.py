"""The robot's body (internal): where it is and how it moves, and its middleware.

Poses and snapshots of positions (``_pose``, ``_positions``), speed profiles in
closed form (``_phases``, ``_profiles``: the thesis's equations 2-5), and the
middleware contract a simulator or a real robot implements (``_middleware``).

Imports only the ground (``cas_async._errors``, ``cas_async._types``).
"""

__all__: list[str] = []
