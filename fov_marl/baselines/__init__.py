"""Policies (``pfcbf``, ``ideal``, ``lloyd-pf``, ``random``, ``learned``) and their registry.

>>> from fov_marl.baselines import make_policy
>>> policy = make_policy("random", env)
>>> policy.reset(seed=0)
>>> actions = policy.act(obs)
"""

from fov_marl.baselines import learned, pfcbf, random_policy  # noqa: F401  (register the policies)
from fov_marl.baselines.registry import Policy, available_policies, make_policy, register_policy

__all__ = ["Policy", "available_policies", "make_policy", "register_policy"]
