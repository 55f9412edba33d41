"""Universal Robots controllers: what RTDE and the dashboard server say, in our words."""
