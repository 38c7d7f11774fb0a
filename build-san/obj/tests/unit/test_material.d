build-san/obj/tests/unit/test_material.o: tests/unit/test_material.c \
 common/integrator.h common/accel.h common/scene.h common/vec.h \
 common/camera.h common/sampler.h common/rng.h common/light.h \
 common/tile.h common/imgio.h common/log.h common/material.h
common/integrator.h:
common/accel.h:
common/scene.h:
common/vec.h:
common/camera.h:
common/sampler.h:
common/rng.h:
common/light.h:
common/tile.h:
common/imgio.h:
common/log.h:
common/material.h:
