build-san/obj/common/integrator.o: common/integrator.c \
 common/integrator.h common/accel.h common/scene.h common/vec.h \
 common/camera.h common/sampler.h common/rng.h common/light.h \
 common/tile.h common/imgio.h common/log.h common/material.h \
 common/motion.h
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
common/motion.h:
