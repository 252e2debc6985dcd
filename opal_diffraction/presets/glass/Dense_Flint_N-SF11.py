# Dense Flint N-SF11: n_d 1.78472, Abbe number V_d 25.68 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 25.68
opal.node_ior = 1.78472
