"""A learnable Contract: the policy scales this robot's bids (action 0: honest, 1: doubled)."""

from cas_async.rl import PolicyLayer
from contract_net.app import Contract


class LearnedContract(PolicyLayer, Contract):
    def cost(self, distance: float) -> float:
        return distance * (1.0 + float(self.decide(distance)))
