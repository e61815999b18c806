"""Where a robot's item operations are decided when the ledger lives in another process.

In one process, :class:`~cas_async.sim.SimulatedHands` changes the Environment's
ledger directly. When a simulation spans processes, one process (the world) keeps
the only ledger, so that an item can never be lost or held twice; the others give
their Environment an :class:`ItemAuthority` that forwards each operation there and
waits for the answer. The hands, and the layers above them, do not change.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from .._types import ItemId, RobotId

__all__ = ["ItemAuthority"]


class ItemAuthority(ABC):
    """The item operations of :class:`~cas_async.sim.Environment`, decided elsewhere.

    Each raises what the Environment's method of the same name raises
    (``SimulationError``, ``UnknownRobotError``), with the authority's message.
    """

    @abstractmethod
    async def create_item(self, robot_id: RobotId, t: float) -> ItemId:
        """See :meth:`Environment.create_item`."""

    @abstractmethod
    async def hand_over(
        self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, *, reach: float
    ) -> None:
        """See :meth:`Environment.hand_over`."""

    @abstractmethod
    async def retire_item(self, item: ItemId, robot_id: RobotId, t: float) -> None:
        """See :meth:`Environment.retire_item`."""

    @abstractmethod
    async def accept_from(self, receiver: RobotId, giver: RobotId) -> None:
        """See :meth:`Environment.accept_from`."""

    @abstractmethod
    async def refuse_from(self, receiver: RobotId, giver: RobotId) -> None:
        """See :meth:`Environment.refuse_from`."""

    @abstractmethod
    async def held_by(self, robot_id: RobotId) -> tuple[ItemId, ...]:
        """See :meth:`ItemLedger.held_by`."""
