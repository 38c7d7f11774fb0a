build2/obj/common/render/tile.o: common/render/tile.c \
 common/render/tile.h common/image/imgio.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
