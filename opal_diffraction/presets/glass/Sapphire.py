# Sapphire: n_d 1.768, Abbe number V_d 72.2 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 72.2
opal.node_ior = 1.768
