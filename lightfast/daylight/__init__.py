"""Daylight illumination for camera tracking (Krawez et al., RA-L 2021): sun position, light sets, normalized
radiosity of sun, sky and ground (§III-A/B/E), and the lighting map that holds them."""
