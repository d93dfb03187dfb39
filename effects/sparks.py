"""Sparks: hot, fast, short-lived, additive; white-yellow cooling through orange to dark red, drawn
as short streaks along the velocity (motion blur)."""

EMITTER = {
    "blend": "additive",
    "lifetime": 1.2,
    "lifetime_randomness": 0.5,
    "speed": [3.0, 7.0],
    "spread": 20.0,
    "drag": 0.4,
    "color": [[0.0, 14.0, 11.0, 7.0], [0.15, 9.0, 4.8, 1.3], [0.5, 4.0, 1.2, 0.15], [1.0, 1.0, 0.12, 0.02]],
    "alpha": [[0.0, 1.0], [0.8, 0.8], [1.0, 0.0]],
    "size": [[0.0, 0.018], [1.0, 0.008]],
    "streak": 0.025,
}
