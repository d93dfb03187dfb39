"""Dust: many small, slow, drag-dominated motes, alpha-blended in a warm grey, fading in and out."""

EMITTER = {
    "blend": "alpha",
    "lifetime": 6.0,
    "lifetime_randomness": 0.3,
    "speed": [0.3, 1.6],
    "spread": 70.0,
    "drag": 1.8,
    "color": [[0.0, 0.55, 0.48, 0.40], [1.0, 0.42, 0.38, 0.33]],
    "alpha": [[0.0, 0.0], [0.08, 0.35], [0.7, 0.25], [1.0, 0.0]],
    "size": [[0.0, 0.05], [1.0, 0.09]],
    "size_randomness": 0.5,
}
