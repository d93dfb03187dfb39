"""Smoke: soft, slow, buoyant puffs that grow and fade, alpha-blended (order independent) and
darker where thick; turbulence makes it curl."""

EMITTER = {
    "blend": "alpha",
    "lifetime": 4.0,
    "lifetime_randomness": 0.3,
    "speed": [0.2, 0.6],
    "spread": 25.0,
    "drag": 1.2,
    "gravity_scale": 0.0,  # the carrier gas is neutrally buoyant once it has cooled
    "buoyancy": 1.6,
    "cooling": 2.5,
    "turbulence": 1.0,
    "color": [[0.0, 0.36, 0.34, 0.32], [0.5, 0.26, 0.25, 0.24], [1.0, 0.20, 0.20, 0.20]],
    "alpha": [[0.0, 0.0], [0.1, 0.16], [0.55, 0.10], [1.0, 0.0]],
    "size": [[0.0, 0.18], [1.0, 1.0]],
    "size_randomness": 0.35,
}
