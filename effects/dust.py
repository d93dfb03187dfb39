"""Dust: many small, slow, drag-dominated motes, alpha-blended in a warm grey, fading in and out."""

EMITTER = {
    "blend": "alpha",
    "lifetime": 6.0,
    "lifetime_randomness": 0.3,
    "speed": [0.3, 1.6],
    "spread": 70.0,
    "drag": 1.8,
    "color": [[0.0, 0.30, 0.25, 0.19], [1.0, 0.24, 0.21, 0.18]],
    "alpha": [[0.0, 0.0], [0.1, 0.16], [0.6, 0.10], [1.0, 0.0]],
    "size": [[0.0, 0.10], [1.0, 0.32]],
    "size_randomness": 0.5,
}
