"""Performance-based character control (Ishigaki et al. 2009): virtual features, intention
recognition, intentional contacts, kinematic composition. Library modules import no rclpy; the
node is ``control_node``."""
