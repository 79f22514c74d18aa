# demons: the field library (lib/field) and lib/img beneath it
demons_LIBS := field img
