build2/obj/common/render/raydiff.o: common/render/raydiff.c \
 common/render/raydiff.h common/scene/camera.h common/scene/sampler.h \
 common/base/rng.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/texture.h \
 common/image/mip.h
common/render/raydiff.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/texture.h:
common/image/mip.h:
