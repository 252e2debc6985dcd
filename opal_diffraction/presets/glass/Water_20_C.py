# Water (20 C): n_d 1.333, Abbe number V_d 55.7 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 55.7
opal.node_ior = 1.333
