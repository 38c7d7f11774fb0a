build2/obj/common/render/passes.o: common/render/passes.c \
 common/render/passes.h common/scene/medium.h common/scene/scene_limits.h \
 common/base/vec.h common/scene/scene.h common/scene/motion.h
common/render/passes.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/scene/scene.h:
common/scene/motion.h:
