build-san/obj/common/motion.o: common/motion.c common/motion.h \
 common/scene.h common/vec.h
common/motion.h:
common/scene.h:
common/vec.h:
