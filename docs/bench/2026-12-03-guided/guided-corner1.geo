scene corner1, database guided-corner1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 2 | 3907 | 90.7 % | 97.7 % | 99.2 % | 0.24 | 3907 | 86.0 % | 96.5 % | 99.0 % |
| view0.png view2.png | 2 | 2296 | 87.6 % | 95.1 % | 98.6 % | 0.27 | 2296 | 80.4 % | 93.2 % | 97.0 % |
| view0.png view3.png | 2 | 1267 | 77.6 % | 86.4 % | 90.1 % | 0.35 | 1267 | 70.9 % | 83.9 % | 87.5 % |
| view0.png view4.png | 2 | 641 | 17.6 % | 21.1 % | 23.2 % | 174.53 | 641 | 16.2 % | 20.7 % | 22.2 % |
| view1.png view2.png | 2 | 3929 | 93.4 % | 98.1 % | 99.4 % | 0.20 | 3929 | 87.3 % | 96.8 % | 99.2 % |
| view1.png view3.png | 2 | 1083 | 87.6 % | 95.1 % | 97.3 % | 0.24 | 1083 | 80.8 % | 93.3 % | 96.5 % |
| view1.png view4.png | 2 | 1093 | 80.6 % | 87.2 % | 90.1 % | 0.31 | 1093 | 73.1 % | 85.4 % | 89.7 % |
| view2.png view3.png | 2 | 3876 | 92.6 % | 98.5 % | 99.6 % | 0.20 | 3876 | 87.2 % | 97.3 % | 99.5 % |
| view2.png view4.png | 6 | 2275 | 88.1 % | 96.3 % | 100.0 % | 0.24 | 2275 | 80.9 % | 93.4 % | 97.6 % |
| view3.png view4.png | 2 | 3879 | 92.9 % | 98.4 % | 99.6 % | 0.22 | 3879 | 87.0 % | 97.3 % | 99.4 % |
| all pairs |  | 24246 | 88.1 % | 94.4 % | 96.4 % | 0.24 | 24246 | 82.1 % | 92.9 % | 95.7 % |

model: 5/5 images registered, 5534 points
relative rotation error (every pair of images, no alignment): mean 0.016° max 0.027°
after a similarity alignment of the camera centres: centre error mean 0.0023 max 0.0031 (scene units), rotation error mean 0.019° max 0.028°
