"""MuJoCo physics character PD-tracking reconstructed postures (Shum & Ho 2012), with virtual joints, objects and pushes."""
