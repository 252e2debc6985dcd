"""Every light kind (point, spot, sun, area, emissive mesh, environment map): emission, sampling of incident light, pdfs. Imports util/, spectral/, scene/."""
