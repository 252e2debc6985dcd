"""Random numbers and camera rays: the Sobol' sampler, the camera, ray differentials (pixel footprints). Imports util/, spectral/ and scene/."""
