"""ECTS dual-arm execution of a repositioning plan, closed loop on vision."""
