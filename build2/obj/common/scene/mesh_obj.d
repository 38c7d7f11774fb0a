build2/obj/common/scene/mesh_obj.o: common/scene/mesh_obj.c \
 common/scene/mesh_obj.h common/base/asset.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/image/image_load.h common/image/mip.h common/base/log.h \
 common/scene/texture.h
common/scene/mesh_obj.h:
common/base/asset.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/image/image_load.h:
common/image/mip.h:
common/base/log.h:
common/scene/texture.h:
