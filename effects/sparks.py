"""Sparks: hot, fast, short-lived, additive; white-yellow cooling through orange to dark red, drawn
as short streaks along the velocity (motion blur)."""

EMITTER = {
    "blend": "additive",
    "lifetime": 1.2,
    "lifetime_randomness": 0.5,
    "speed": [3.0, 7.0],
    "spread": 20.0,
    "drag": 0.4,
    "color": [[0.0, 6.0, 5.0, 3.2], [0.15, 4.0, 2.2, 0.6], [0.5, 2.0, 0.6, 0.08], [1.0, 0.5, 0.06, 0.01]],
    "alpha": [[0.0, 1.0], [0.8, 0.8], [1.0, 0.0]],
    "size": [[0.0, 0.018], [1.0, 0.008]],
    "streak": 0.025,
}
