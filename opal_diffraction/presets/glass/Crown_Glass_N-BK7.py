# Crown Glass N-BK7: n_d 1.5168, Abbe number V_d 64.17 (Sellmeier data; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'BK7'
opal.abbe_number = 64.17
opal.node_ior = 1.5168
