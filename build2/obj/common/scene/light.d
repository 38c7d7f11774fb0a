build2/obj/common/scene/light.o: common/scene/light.c \
 common/scene/light.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/base/log.h
common/scene/light.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/log.h:
