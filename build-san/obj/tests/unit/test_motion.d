build-san/obj/tests/unit/test_motion.o: tests/unit/test_motion.c \
 common/integrator.h common/accel.h common/scene.h common/vec.h \
 common/camera.h common/sampler.h common/rng.h common/light.h \
 common/tile.h common/imgio.h common/log.h common/motion.h \
 common/scene_json.h common/asset.h
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
common/motion.h:
common/scene_json.h:
common/asset.h:
