build2/obj/tests/unit/test_camera.o: tests/unit/test_camera.c \
 common/scene/camera.h common/scene/sampler.h common/base/rng.h \
 common/scene/scene.h common/base/vec.h common/scene/motion.h \
 common/scene/scene_limits.h
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
