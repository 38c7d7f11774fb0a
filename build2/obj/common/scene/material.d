build2/obj/common/scene/material.o: common/scene/material.c \
 common/scene/material.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h
common/scene/material.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
