# Black opal preset (black opal: a dark potch body under the play of colour, the most saturated flashes).
# Spheres D_s = 245 +- 45 nm of silica (n_s 1.45), voids n_void 1.33 (water):
# n_eff 1.4198, Bragg colour at normal incidence 464-672 nm (lambda = 2 d111 n_eff,
# d111 = sqrt(2/3) D_s; docs/physics.md section 5.2); 60 ordered layers, mosaic spread 6 deg;
# 800 volume domains, layered (111) normals within 35 deg of the object's Z axis.
import bpy
opal = bpy.context.material.opal

opal.grating = True
opal.grating_type = 'REFLECTION'
opal.lattice = 'BRAGG'
opal.grating_direction = 'ATTRIBUTE'
opal.rotation = 0.0
opal.period = 550.0
opal.slit_width = 275.0
opal.sphere_diameter = 245.0
opal.sphere_ior = 1.45
opal.void_ior = 1.33
opal.layers = 60
opal.mosaic_spread = 6.0
opal.domain_count = 800
opal.domain_size_spread = 0.6
opal.domain_orientation = 'LAYERED'
opal.domain_axis_spread = 35.0
opal.diameter_spread = 45.0
opal.body_color = [0.008, 0.008, 0.01]
opal.body_roughness = 0.03
opal.body_transmission = 0.0
opal.node_ior = 1.45
opal.dispersion = 'NONE'
