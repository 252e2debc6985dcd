"""The light pass: paths from the lights through mirrors, glass and gratings, deposited as caustics and grating records, and connected to the camera."""
