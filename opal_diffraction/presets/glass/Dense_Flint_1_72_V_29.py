# Dense Flint (1.72, V 29): n_d 1.72, Abbe number V_d 29 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 29.0
opal.node_ior = 1.72
