build2/obj/common/scene/scene.o: common/scene/scene.c \
 common/scene/scene.h common/base/vec.h common/scene/motion.h \
 common/scene/scene_limits.h common/base/log.h common/scene/medium.h \
 common/scene/texture.h common/image/mip.h
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/log.h:
common/scene/medium.h:
common/scene/texture.h:
common/image/mip.h:
