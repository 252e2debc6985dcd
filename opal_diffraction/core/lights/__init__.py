"""Every light kind (point, spot, sun, area, emissive mesh, environment map): emission of light paths aimed at the casters, sampling of incident light, pdfs. Imports util/, spectral/, scene/."""
