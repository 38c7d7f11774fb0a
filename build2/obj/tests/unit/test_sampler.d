build2/obj/tests/unit/test_sampler.o: tests/unit/test_sampler.c \
 common/scene/sampler.h common/base/rng.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h
common/scene/sampler.h:
common/base/rng.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
