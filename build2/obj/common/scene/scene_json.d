build2/obj/common/scene/scene_json.o: common/scene/scene_json.c \
 common/scene/scene_json.h common/base/asset.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/base/log.h common/scene/medium.h common/scene/grid.h \
 common/scene/nvdb.h common/scene/mesh_obj.h common/scene/sampler.h \
 common/base/rng.h common/image/image_load.h common/image/mip.h \
 common/scene/texture.h
common/scene/scene_json.h:
common/base/asset.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/log.h:
common/scene/medium.h:
common/scene/grid.h:
common/scene/nvdb.h:
common/scene/mesh_obj.h:
common/scene/sampler.h:
common/base/rng.h:
common/image/image_load.h:
common/image/mip.h:
common/scene/texture.h:
