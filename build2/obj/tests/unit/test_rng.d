build2/obj/tests/unit/test_rng.o: tests/unit/test_rng.c common/base/rng.h \
 common/scene/sampler.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h
common/base/rng.h:
common/scene/sampler.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
