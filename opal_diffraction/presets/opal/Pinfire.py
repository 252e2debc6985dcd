# Pinfire opal preset (pinfire: many small domains, pin-point flashes, on a dark grey body).
# Spheres D_s = 240 +- 45 nm of silica (n_s 1.45), voids n_void 1.33 (water):
# n_eff 1.4198, Bragg colour at normal incidence 452-661 nm (lambda = 2 d111 n_eff,
# d111 = sqrt(2/3) D_s; docs/physics.md section 5.2); 30 ordered layers, mosaic spread 8 deg;
# 5000 volume domains, layered (111) normals within 40 deg of the object's Z axis.
import bpy
opal = bpy.context.material.opal

opal.grating = True
opal.grating_type = 'REFLECTION'
opal.lattice = 'BRAGG'
opal.grating_direction = 'ATTRIBUTE'
opal.rotation = 0.0
opal.period = 550.0
opal.slit_width = 275.0
opal.sphere_diameter = 240.0
opal.sphere_ior = 1.45
opal.void_ior = 1.33
opal.layers = 30
opal.mosaic_spread = 8.0
opal.domain_count = 5000
opal.domain_size_spread = 0.8
opal.domain_orientation = 'LAYERED'
opal.domain_axis_spread = 40.0
opal.diameter_spread = 45.0
opal.body_color = [0.03, 0.03, 0.035]
opal.body_roughness = 0.05
opal.body_transmission = 0.0
opal.node_ior = 1.45
opal.dispersion = 'NONE'
