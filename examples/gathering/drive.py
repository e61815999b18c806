"""The robotic layer, ``Drive``: the only one that moves the robot."""

from __future__ import annotations

from cas_async import Layer, Message, Middleware

from .messages import Arrived, DriveTo

__all__ = ["Drive"]


class Drive(Layer):
    """Answers each ``DriveTo`` once the robot has driven there, with where it stopped.

    It moves the robot through its :class:`~cas_async.Middleware`: a
    :class:`~cas_async.sim.SimulatedMiddleware` in a simulation, a hardware
    driver on a real robot; the layer is the same.

    Args:
        middleware: the robot's motion and perception.
    """

    def __init__(self, middleware: Middleware) -> None:
        self.middleware = middleware

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case DriveTo(x=x, y=y):
                pose = await self.middleware.move_to(x, y)
                return Arrived(pose.x, pose.y)
        return None
