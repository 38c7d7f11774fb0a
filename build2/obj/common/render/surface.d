build2/obj/common/render/surface.o: common/render/surface.c \
 common/render/surface.h common/render/accel.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/scene/light.h common/scene/material.h
common/render/surface.h:
common/render/accel.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/light.h:
common/scene/material.h:
