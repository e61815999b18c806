"""The scenario file and the application contract (internal).

``_config`` turns TOML tables into frozen dataclasses (``setting()``, errors naming
file and key); ``_loader`` reads a scenario end to end (``app``, ``[run]``,
``[world]``, ``[network]``, ``[faults]``, the app's sections, ``--set``);
``_app`` is the contract an application implements, ``_app_import`` imports and
checks one, ``_layers`` replaces levels of its stack (``[layers]``), ``_objective``
says what a mission is for, ``_scene`` what the views draw; ``_capacity`` refuses
sizes this machine cannot hold, and ``_run_transport`` builds the transport a
scenario names.

Imports the library's faces and internals below it, and ``scenario.output``.
"""

__all__: list[str] = []
