build2/obj/common/scene/sampler.o: common/scene/sampler.c \
 common/scene/sampler.h common/base/rng.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h
common/scene/sampler.h:
common/base/rng.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
