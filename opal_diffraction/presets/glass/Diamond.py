# Diamond: n_d 2.4175, Abbe number V_d 55.3 (Sellmeier data; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'DIAMOND'
opal.abbe_number = 55.3
opal.node_ior = 2.4175
