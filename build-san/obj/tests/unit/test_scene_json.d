build-san/obj/tests/unit/test_scene_json.o: tests/unit/test_scene_json.c \
 common/scene_json.h common/asset.h common/scene.h common/vec.h
common/scene_json.h:
common/asset.h:
common/scene.h:
common/vec.h:
