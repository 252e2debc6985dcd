# The source paper's opal (Kobayashi & Kawai; docs/physics.md section 5.1): a surface grating, every
# triangle one grating of parallel slits, all oriented consistently (the object's X axis projected onto
# each face), one period of 550 nm (100 coherent slits, 2 um long), on a dark body. Not a physical opal:
# colour moves to the red away from the mirror direction.
import bpy
opal = bpy.context.material.opal

opal.grating = True
opal.grating_type = 'REFLECTION'
opal.lattice = 'LINES'
opal.grating_direction = 'ATTRIBUTE'
opal.rotation = 0.0
opal.period = 550.0
opal.slit_width = 275.0
opal.slit_count = 100
opal.coherence_length = 2.0
opal.domain_count = 1
opal.body_color = [0.12, 0.12, 0.13]
opal.body_roughness = 0.3
opal.body_transmission = 0.0
opal.node_ior = 1.45
opal.dispersion = 'NONE'
