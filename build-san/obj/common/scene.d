build-san/obj/common/scene.o: common/scene.c common/scene.h common/vec.h \
 common/log.h common/motion.h
common/scene.h:
common/vec.h:
common/log.h:
common/motion.h:
