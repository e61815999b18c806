"""Running one scenario (internal): here, in windows, or in worker processes.

``_runner`` (:class:`~cas_async.scenario.ScenarioRun`) builds the mission, watches
its objective, samples and measures it (``_measure``); ``_placement`` decides where
its robots run, one object per mode: here, sampled (``_sampled``); here in windows
of the network latency (``_windowed``); or in worker processes
(``cas_async.scenario._processes``). ``_run_scenario`` is a whole run as one
coroutine, ``_background`` a run beside an asyncio service, ``_listener`` what a run
tells whoever follows it, ``_drop_policy`` which drops fail it.
"""

__all__: list[str] = []
