"""Velocity models of one ball: Eq. (24), the analytical solution, the point-contact
model and the full friction model, and the name -> model registry."""
