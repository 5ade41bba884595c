"""Problems: parameters ↔ residuals (free, driven, joint on one abstraction) and what is evaluated on them, compiled."""
