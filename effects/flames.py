"""Flames: short-lived, buoyant, additive; white-yellow at the root through orange and dark red,
flickering with turbulence. Pair with a smoke sub-emitter on death for flame → smoke."""

EMITTER = {
    "blend": "additive",
    "lifetime": 0.7,
    "lifetime_randomness": 0.5,
    "speed": [0.1, 0.5],
    "spread": 15.0,
    "drag": 3.0,
    "gravity_scale": 0.0,
    "buoyancy": 5.0,
    "cooling": 0.6,
    "turbulence": 1.0,
    "color": [[0.0, 1.6, 1.25, 0.7], [0.15, 1.5, 0.75, 0.18], [0.45, 0.9, 0.25, 0.04],
              [0.75, 0.3, 0.05, 0.015], [1.0, 0.04, 0.015, 0.01]],
    "alpha": [[0.0, 0.0], [0.06, 0.4], [0.5, 0.25], [1.0, 0.0]],
    "size": [[0.0, 0.22], [0.35, 0.14], [1.0, 0.04]],
    "size_randomness": 0.4,
    "streak": 0.06,  # stretched along the rising velocity: flame tongues, not dots
}
