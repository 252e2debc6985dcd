# Boulder opal preset (boulder opal: a thin seam on brown ironstone, silica-filled voids (low contrast), planes parallel to the seam).
# Spheres D_s = 225 +- 30 nm of silica (n_s 1.45), voids n_void 1.4 (silica cement):
# n_eff 1.4372, Bragg colour at normal incidence 458-598 nm (lambda = 2 d111 n_eff,
# d111 = sqrt(2/3) D_s; docs/physics.md section 5.2); 30 ordered layers, mosaic spread 6 deg;
# 400 volume domains, layered (111) normals within 15 deg of the object's Z axis.
import bpy
opal = bpy.context.material.opal

opal.grating = True
opal.grating_type = 'REFLECTION'
opal.lattice = 'BRAGG'
opal.grating_direction = 'ATTRIBUTE'
opal.rotation = 0.0
opal.period = 550.0
opal.slit_width = 275.0
opal.sphere_diameter = 225.0
opal.sphere_ior = 1.45
opal.void_ior = 1.4
opal.layers = 30
opal.mosaic_spread = 6.0
opal.domain_count = 400
opal.domain_size_spread = 0.5
opal.domain_orientation = 'LAYERED'
opal.domain_axis_spread = 15.0
opal.diameter_spread = 30.0
opal.body_color = [0.06, 0.035, 0.02]
opal.body_roughness = 0.1
opal.body_transmission = 0.0
opal.node_ior = 1.45
opal.dispersion = 'NONE'
