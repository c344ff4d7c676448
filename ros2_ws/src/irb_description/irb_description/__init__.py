"""IRB 1600 description: URDF, parameters, kinematics, dynamics, friction (no ROS imports)."""
