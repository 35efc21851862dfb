"""Coupled stepping: granular RK4 with the solid (rigid, plate or beam) at the interface."""
