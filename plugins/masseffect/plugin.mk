# lib/field: the Jacobian; lib/img: dilation by a ball in mm
masseffect_LIBS := field img
