"""Layers applied after a law, each separate, composable and counting its clips.

    constraints.py        actuator box, jerk limit, speed saturation (seed 001)
    constraint_kernels.py their compiled passes (numba)
    safety.py             the safety backstop: clips a road command only when it is unsafe
    safety_kernels.py     its compiled pass (numba)
"""
