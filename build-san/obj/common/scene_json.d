build-san/obj/common/scene_json.o: common/scene_json.c \
 common/scene_json.h common/asset.h common/scene.h common/vec.h \
 common/log.h common/mesh_obj.h common/motion.h common/sampler.h \
 common/rng.h
common/scene_json.h:
common/asset.h:
common/scene.h:
common/vec.h:
common/log.h:
common/mesh_obj.h:
common/motion.h:
common/sampler.h:
common/rng.h:
