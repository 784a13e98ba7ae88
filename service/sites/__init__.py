"""Sites: the hub that tracks each site, the registry rows of its zones and lines, its views."""
