"""The LLI's configuration vocabulary (LLI_Config and LLI_ReversingResult, Staubli LLI s7.4):
what a joint vector's shoulder, elbow and wrist are called, and why an inverse kinematics call
failed. kinematics.py labels joint vectors with it and solves for it; the controller interface
(controller.py) carries it. No numbers here, so the interface can name it without loading the
solver.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Shoulder", "PosNeg", "Config", "ReversingResult", "BRANCHES"]


class Shoulder(enum.IntEnum):
    """LLI_ShoulderConfig."""
    SAME = 0
    LEFTY = 1
    RIGHTY = 2
    FREE = 3


class PosNeg(enum.IntEnum):
    """LLI_PositiveNegativeConfig (elbow and wrist)."""
    SAME = 0
    POSITIVE = 1
    NEGATIVE = 2
    FREE = 3


@dataclass(frozen=True)
class Config:
    """LLI_RxConfig. As a request, SAME means "as q_near" and FREE "any"."""
    shoulder: Shoulder = Shoulder.FREE
    elbow: PosNeg = PosNeg.FREE
    wrist: PosNeg = PosNeg.FREE


class ReversingResult(enum.IntEnum):
    """LLI_ReversingResult."""
    OK = 0
    NO_CONVERGENCE = 1
    OUT_OF_JNT_RANGE = 2
    OUT_OF_WORKSPACE = 3
    INVALID_CONFIG = 4
    INVALID_ORIENTATION = 5
    UNSUPPORTED_KINEMATICS = 6
    UNCONSTRAINT_FRAME = 7
    INVALID_ERROR_CODE = 8


# The 8 branches of the closed form, in the order of `solve_batch`'s second axis:
# index = 4 * shoulder + 2 * elbow + wrist, with 0 = RIGHTY / POSITIVE and 1 = LEFTY / NEGATIVE.
BRANCHES: tuple[Config, ...] = tuple(
    Config(s, e, w)
    for s in (Shoulder.RIGHTY, Shoulder.LEFTY)
    for e in (PosNeg.POSITIVE, PosNeg.NEGATIVE)
    for w in (PosNeg.POSITIVE, PosNeg.NEGATIVE))
