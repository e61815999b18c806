"""Contracts that end a run early: every robot stops at once, or nothing ever happens."""

from contract_net.app import Contract


class EarlyContract(Contract):
    """Stops at its first batch: every robot stops before any task is done."""

    def termination_condition(self) -> bool:
        return True


class LazyContract(Contract):
    """Never announces a task: no message, no timer, no motion, ever (a quiet swarm)."""

    async def inner_process(self) -> None:
        pass
